// CPU rasterizer for render.exr/.png and preview frames: the welded element mesh with smooth
// per-vertex radiosity, near-plane clipped, z-buffered, perspective-correct, supersampled.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "core/error.h"
#include "core/parallel.h"
#include "formfactor/clip.h"
#include "output/output.h"
#include "output/welded_mesh.h"

namespace hemirad::output {
namespace {

constexpr int kSupersample = 3;          // samples per pixel along each axis, box-filtered
constexpr std::int64_t kSubpixel = 256;  // fixed-point steps per sample: exact edge functions
constexpr std::int64_t kHalfSample = kSubpixel / 2;
constexpr double kNearFraction = 1e-4;  // near plane distance as a fraction of the mesh diagonal
// Triangles are clipped to |x|, |y| <= kGuardBand·w rather than to the image (|x| <= w), so
// clipping never cuts visible edges yet fixed-point coordinates stay far from int64 overflow.
constexpr double kGuardBand = 2.0;
constexpr int kStripRows = 16;  // pixel rows rasterized at a time: bounds sample memory

// Homogeneous clip coordinates (x, y, w = distance in front of the camera) and the colour.
struct ClipVertex {
    glm::dvec3 pos;
    glm::dvec3 colour;
};

// One triangle in fixed-point sample coordinates (y down), wound so that the edge functions
// below are non-negative inside (clockwise as seen on the screen).
struct ScreenTriangle {
    std::int64_t x[3], y[3];
    double inv_w[3];  // 1/w: depth, and the perspective-correct weight
    glm::dvec3 colour_over_w[3];
    int first_row, last_row;  // sample rows it may cover
};

// A clip plane: a vertex is kept where dot(plane.xyz, pos) + plane.w >= 0.
using Plane = glm::dvec4;

double distance(const Plane& plane, const ClipVertex& v) {
    return glm::dot(glm::dvec3(plane), v.pos) + plane.w;
}

// The point where edge (inside, outside) crosses `plane`, computed from the inside end so a
// shared edge clipped by its two triangles yields bit-identical points (no cracks).
ClipVertex crossing(const ClipVertex& inside, const ClipVertex& outside, double d_in, double d_out) {
    const double t = d_in / (d_in - d_out);
    return {inside.pos + t * (outside.pos - inside.pos), inside.colour + t * (outside.colour - inside.colour)};
}

// Clips against one plane (formfactor::clip_convex); returns the output vertex count (<= n + 1).
int clip_polygon(const ClipVertex* in, int n, ClipVertex* out, const Plane& plane) {
    const auto value = [&](const ClipVertex& v) { return distance(plane, v); };
    const auto cross = [](const ClipVertex& a, const ClipVertex& b, double da, double db) {
        return da >= 0.0 ? crossing(a, b, da, db) : crossing(b, a, db, da);
    };
    return formfactor::clip_convex(in, n, value, cross, out);
}

std::int64_t floor_div(std::int64_t a, std::int64_t b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}
std::int64_t ceil_div(std::int64_t a, std::int64_t b) {
    return -floor_div(-a, b);
}

// Edge function of edge a→b at p: twice the signed area of (a, b, p).
std::int64_t edge(std::int64_t ax, std::int64_t ay, std::int64_t bx, std::int64_t by, std::int64_t px,
                  std::int64_t py) {
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

// Top-left fill rule for interiors with non-negative edge functions in y-down coordinates:
// a sample exactly on an edge belongs to the triangle only if that edge is a top or left one,
// so a sample on an edge shared by two triangles is drawn exactly once.
bool is_top_left(std::int64_t dx, std::int64_t dy) {
    return dy < 0 || (dy == 0 && dx > 0);
}

// Projects the camera-space scene into screen triangles, clipping where needed.
class TriangleSetup {
public:
    TriangleSetup(const View& view, int width, int height, double znear)
        : world_to_camera_(glm::inverse(view.camera_to_world)),
          camera_to_world_(view.camera_to_world),
          samples_x_(double(width) * kSupersample),
          samples_y_(double(height) * kSupersample) {
        const double f = 1.0 / std::tan(0.5 * view.yfov);
        // The image's own aspect, not the camera's, so a mis-sized image is never stretched.
        scale_ = glm::dvec2(f * double(height) / double(width), f);
        planes_[0] = Plane(0.0, 0.0, 1.0, -znear);
        planes_[1] = Plane(-1.0, 0.0, kGuardBand, 0.0);
        planes_[2] = Plane(1.0, 0.0, kGuardBand, 0.0);
        planes_[3] = Plane(0.0, -1.0, kGuardBand, 0.0);
        planes_[4] = Plane(0.0, 1.0, kGuardBand, 0.0);
    }

    // Adds the screen triangles of one mesh triangle. A triangle seen from behind is skipped: its
    // twin draws a double-sided surface's back, and a one-sided surface's back is culled, as glTF
    // asks of viewers (doubleSided false), so an interior of walls facing in is seen into from
    // outside as every engine shows it. (The solve still lets such a back block light.)
    void add(const WeldedNode& node, std::size_t triangle, std::vector<ScreenTriangle>& out) const {
        glm::dvec3 p[3];
        ClipVertex v[3];
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t id = node.indices[3 * triangle + k];
            p[k] = glm::dvec3(world_to_camera_ * glm::dvec4(node.positions[id], 1.0));
            v[k] = {glm::dvec3(scale_.x * p[k].x, scale_.y * p[k].y, -p[k].z), node.radiosity[id]};
        }
        const double facing = glm::dot(glm::cross(p[1] - p[0], p[2] - p[0]), -p[0]);  // eye at 0
        if (facing == 0.0) return;                                                    // edge-on
        if (facing < 0.0) return;
        clip_and_emit(v, out);
    }

    // Adds a see-through triangle, both faces alike, its colour `own` (what it shows of its own).
    void add_glass(const std::array<glm::dvec3, 3>& corners, const glm::dvec3& own, std::vector<ScreenTriangle>& out) const {
        ClipVertex v[3];
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 p = glm::dvec3(world_to_camera_ * glm::dvec4(corners[k], 1.0));
            v[k] = {glm::dvec3(scale_.x * p.x, scale_.y * p.y, -p.z), own};
        }
        clip_and_emit(v, out);
    }

    // The world direction of the view ray through sample (i, j) (not of unit length).
    glm::dvec3 ray(int i, int j) const {
        const double x = 2.0 * (double(i) + 0.5) / samples_x_ - 1.0;
        const double y = 1.0 - 2.0 * (double(j) + 0.5) / samples_y_;
        return glm::dmat3(camera_to_world_) * glm::dvec3(x / scale_.x, y / scale_.y, -1.0);
    }
    glm::dvec3 eye() const { return glm::dvec3(camera_to_world_[3]); }

private:
    void clip_and_emit(const ClipVertex (&tri)[3], std::vector<ScreenTriangle>& out) const {
        ClipVertex buffers[2][3 + 5];  // a triangle through 5 planes, one vertex more per plane
        std::copy(tri, tri + 3, buffers[0]);
        int n = 3, current = 0;
        for (const Plane& plane : planes_) {
            const bool all_inside = std::all_of(buffers[current], buffers[current] + n,
                                                [&](const ClipVertex& c) { return distance(plane, c) >= 0.0; });
            if (all_inside) continue;  // the common case: no new vertices, no rounding
            n = clip_polygon(buffers[current], n, buffers[1 - current], plane);
            current = 1 - current;
            if (n < 3) return;
        }
        for (int k = 1; k + 1 < n; ++k) {
            emit(buffers[current][0], buffers[current][k], buffers[current][k + 1], out);
        }
    }

    void emit(const ClipVertex& a, const ClipVertex& b, const ClipVertex& c, std::vector<ScreenTriangle>& out) const {
        ScreenTriangle t;
        const ClipVertex* v[3] = {&a, &b, &c};
        for (int k = 0; k < 3; ++k) {
            const double inv_w = 1.0 / v[k]->pos.z;
            const double sx = (0.5 + 0.5 * v[k]->pos.x * inv_w) * samples_x_;
            const double sy = (0.5 - 0.5 * v[k]->pos.y * inv_w) * samples_y_;
            t.x[k] = std::llround(sx * double(kSubpixel));
            t.y[k] = std::llround(sy * double(kSubpixel));
            t.inv_w[k] = inv_w;
            t.colour_over_w[k] = v[k]->colour * inv_w;
        }
        const std::int64_t area2 = edge(t.x[0], t.y[0], t.x[1], t.y[1], t.x[2], t.y[2]);
        if (area2 == 0) return;
        if (area2 < 0) {  // y-down flips orientation; make every triangle wind the same way
            std::swap(t.x[1], t.x[2]);
            std::swap(t.y[1], t.y[2]);
            std::swap(t.inv_w[1], t.inv_w[2]);
            std::swap(t.colour_over_w[1], t.colour_over_w[2]);
        }
        const auto [lo, hi] = std::minmax({t.y[0], t.y[1], t.y[2]});
        t.first_row = int(std::max<std::int64_t>(0, ceil_div(lo - kHalfSample, kSubpixel)));
        t.last_row = int(std::min<std::int64_t>(std::int64_t(samples_y_) - 1, floor_div(hi - kHalfSample, kSubpixel)));
        if (t.first_row <= t.last_row) out.push_back(t);
    }

    glm::dmat4 world_to_camera_, camera_to_world_;
    glm::dvec2 scale_{1.0};
    double samples_x_, samples_y_;
    Plane planes_[5];
};

// A band of sample rows with its z-buffer (1/w, larger is nearer; 0 is nothing) and colours.
struct Strip {
    int first_row = 0, rows = 0, width = 0;  // in samples
    std::vector<double> inv_w;
    std::vector<glm::dvec3> colour;

    void reset(int first, int row_count, int sample_width) {
        first_row = first;
        rows = row_count;
        width = sample_width;
        inv_w.assign(std::size_t(rows) * width, 0.0);
        colour.assign(std::size_t(rows) * width, glm::dvec3(0.0));
    }
};

// Calls shade(sample, 1/w, w0, w1, w2) for each sample of the strip the triangle covers.
template <class Shade>
void for_samples(const ScreenTriangle& t, Strip& strip, const Shade& shade) {
    const auto [x_lo, x_hi] = std::minmax({t.x[0], t.x[1], t.x[2]});
    const std::int64_t i0 = std::max<std::int64_t>(0, ceil_div(x_lo - kHalfSample, kSubpixel));
    const std::int64_t i1 = std::min<std::int64_t>(strip.width - 1, floor_div(x_hi - kHalfSample, kSubpixel));
    const int j0 = std::max(t.first_row, strip.first_row);
    const int j1 = std::min(t.last_row, strip.first_row + strip.rows - 1);
    if (i0 > i1 || j0 > j1) return;

    // Edge k runs from vertex k to k+1; its function is the weight of the vertex opposite.
    std::int64_t step_x[3], step_y[3], row_start[3], bias[3];
    const std::int64_t px = i0 * kSubpixel + kHalfSample, py = std::int64_t(j0) * kSubpixel + kHalfSample;
    for (int k = 0; k < 3; ++k) {
        const int n = (k + 1) % 3;
        const std::int64_t dx = t.x[n] - t.x[k], dy = t.y[n] - t.y[k];
        step_x[k] = -dy * kSubpixel;
        step_y[k] = dx * kSubpixel;
        row_start[k] = edge(t.x[k], t.y[k], t.x[n], t.y[n], px, py);
        bias[k] = is_top_left(dx, dy) ? 0 : -1;
    }
    const double inv_area = 1.0 / double(edge(t.x[0], t.y[0], t.x[1], t.y[1], t.x[2], t.y[2]));

    for (int j = j0; j <= j1; ++j) {
        std::int64_t e[3] = {row_start[0], row_start[1], row_start[2]};
        const std::size_t row = std::size_t(j - strip.first_row) * strip.width;
        for (std::int64_t i = i0; i <= i1; ++i) {
            if (((e[0] + bias[0]) | (e[1] + bias[1]) | (e[2] + bias[2])) >= 0) {
                const double w0 = double(e[1]) * inv_area, w1 = double(e[2]) * inv_area, w2 = double(e[0]) * inv_area;
                const double inv_w = w0 * t.inv_w[0] + w1 * t.inv_w[1] + w2 * t.inv_w[2];
                shade(row + std::size_t(i), inv_w, w0, w1, w2);
            }
            for (int k = 0; k < 3; ++k) e[k] += step_x[k];
        }
        for (int k = 0; k < 3; ++k) row_start[k] += step_y[k];
    }
}

// Draws an opaque triangle: z-buffered.
void rasterize(const ScreenTriangle& t, Strip& strip) {
    for_samples(t, strip, [&](std::size_t s, double inv_w, double w0, double w1, double w2) {
        if (inv_w > strip.inv_w[s]) {
            strip.inv_w[s] = inv_w;
            strip.colour[s] = (w0 * t.colour_over_w[0] + w1 * t.colour_over_w[1] + w2 * t.colour_over_w[2]) / inv_w;
        }
    });
}

// Blends a see-through triangle over the samples it is in front of (the z-buffer is left as it is).
void blend(const ScreenTriangle& t, const glm::dvec3& transmit, Strip& strip) {
    for_samples(t, strip, [&](std::size_t s, double inv_w, double w0, double w1, double w2) {
        if (inv_w > strip.inv_w[s])
            strip.colour[s] = transmit * strip.colour[s] +
                              (w0 * t.colour_over_w[0] + w1 * t.colour_over_w[1] + w2 * t.colour_over_w[2]) / inv_w;
    });
}

// What the strip's samples that hit nothing see of the sky: the dome's exitance where the ray
// leaves it (the far root: the eye is inside the dome, or the ray meets its far side).
void fill_sky(const TriangleSetup& setup, const scene::Sky& sky, const scene::Dome& dome, Strip& strip) {
    const glm::dvec3 o = setup.eye() - dome.centre;
    for (int j = 0; j < strip.rows; ++j) {
        for (int i = 0; i < strip.width; ++i) {
            const std::size_t s = std::size_t(j) * strip.width + std::size_t(i);
            if (strip.inv_w[s] != 0.0) continue;
            const glm::dvec3 d = glm::normalize(setup.ray(i, strip.first_row + j));
            const double b = glm::dot(o, d), c = glm::dot(o, o) - dome.radius * dome.radius;
            const double disc = b * b - c;
            if (!(disc >= 0.0)) continue;
            const double t = -b + std::sqrt(disc);
            if (!(t > 0.0)) continue;
            const double height = o.y + t * d.y;
            if (height < 0.0) continue;  // below the rim: no sky there, and no ground either
            strip.colour[s] = glm::dvec3(M_PI * scene::sky_radiance(sky, std::min(1.0, height / dome.radius)));
        }
    }
}

// The area mean of the drawn radiosity: a see-through surface's irradiance (Surroundings).
glm::dvec3 mean_radiosity(const scene::Scene& scene, const WeldedMesh& welded) {
    glm::dvec3 sum(0.0);
    double area = 0.0;
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (scene.nodes[n].synthetic) continue;
        const WeldedNode& node = welded.nodes[n];
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            const glm::dvec3 a = node.positions[node.indices[3 * t]], b = node.positions[node.indices[3 * t + 1]],
                             c = node.positions[node.indices[3 * t + 2]];
            const double A = 0.5 * glm::length(glm::cross(b - a, c - a));
            sum += A / 3.0 *
                   (node.radiosity[node.indices[3 * t]] + node.radiosity[node.indices[3 * t + 1]] +
                    node.radiosity[node.indices[3 * t + 2]]);
            area += A;
        }
    }
    return area > 0.0 ? sum / area : glm::dvec3(0.0);
}

// Box-filters the strip's samples into its pixel rows of `image`.
void resolve(const Strip& strip, Image& image) {
    const double weight = 1.0 / (kSupersample * kSupersample);
    const int first_pixel_row = strip.first_row / kSupersample;
    for (int y = first_pixel_row; y < first_pixel_row + strip.rows / kSupersample; ++y) {
        for (int x = 0; x < image.width; ++x) {
            glm::dvec3 sum(0.0);
            for (int sy = 0; sy < kSupersample; ++sy) {
                const std::size_t row = std::size_t(y * kSupersample + sy - strip.first_row) * strip.width;
                for (int sx = 0; sx < kSupersample; ++sx) sum += strip.colour[row + x * kSupersample + sx];
            }
            float* pixel = &image.rgb[(std::size_t(y) * image.width + x) * 3];
            for (int c = 0; c < 3; ++c) pixel[c] = float(sum[c] * weight);
        }
    }
}

// Over the nodes drawn: the file's, not the sky dome (synthetic), which would dwarf the scene
// and push the near plane into it, and set the automatic exposure by the sky's brightness.
double mesh_diagonal(const scene::Scene& scene, const WeldedMesh& welded) {
    glm::dvec3 lo(HUGE_VAL), hi(-HUGE_VAL);
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (scene.nodes[n].synthetic) continue;
        for (const glm::dvec3& p : welded.nodes[n].positions) {
            lo = glm::min(lo, p);
            hi = glm::max(hi, p);
        }
    }
    return hi.x >= lo.x ? glm::length(hi - lo) : 0.0;
}

}  // namespace

Image render(const scene::Scene& scene, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
             const View& view, int width, int height, const VertexLight* gathered) {
    return render(scene, weld(scene.nodes.size(), mesh, radiosity, gathered ? &gathered->radiosity : nullptr), view,
                  width, height);
}

Image render(const scene::Scene& scene, const WeldedMesh& welded, const View& view, int width, int height) {
    return render(scene, welded, view, width, height, Surroundings{});
}

std::vector<scene::Triangle> see_through_triangles(const scene::Scene& scene) {
    std::vector<scene::Triangle> out;
    for (const scene::Triangle& t : scene.triangles)
        if (t.material < scene.materials.size() && !scene.materials[t.material].see_through.empty()) out.push_back(t);
    return out;
}

Image render(const scene::Scene& scene, const WeldedMesh& welded, const View& view, int width, int height,
             const Surroundings& around) {
    if (width <= 0 || height <= 0) {
        throw InternalError(fmt::format("output: cannot render a {}x{} image", width, height));
    }
    Image image{width, height, std::vector<float>(std::size_t(width) * height * 3, 0.0f)};
    std::vector<ScreenTriangle> triangles, glass;
    std::vector<glm::dvec3> transmits;  // per glass triangle: the share of the light behind it it passes
    const double diagonal = mesh_diagonal(scene, welded);
    if (diagonal <= 0.0 && !around.sky) return image;  // nothing (or nothing with extent) to draw
    const TriangleSetup setup(view, width, height, kNearFraction * std::max(diagonal, 1e-9 * scene.diagonal()));
    {
        std::size_t count = 0;  // (reserved: a vector doubling as it grows holds both copies at once)
        for (std::size_t n = 0; n < welded.nodes.size(); ++n)
            if (!scene.nodes[n].synthetic) count += welded.nodes[n].triangle_count();
        triangles.reserve(count);
        for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
            if (scene.nodes[n].synthetic) continue;
            for (std::size_t t = 0; t < welded.nodes[n].triangle_count(); ++t) setup.add(welded.nodes[n], t, triangles);
        }
    }
    if (!around.see_through.empty()) {
        const glm::dvec3 irradiance = mean_radiosity(scene, welded);
        for (const scene::Triangle& t : around.see_through) {
            const scene::Material& m = scene.materials.at(t.material);
            const glm::dvec3 colour = (t.rho[0] + t.rho[1] + t.rho[2]) / 3.0;
            const bool tinted = m.see_through.rfind("KHR_materials_transmission", 0) == 0;
            const double a = std::clamp(m.opacity, 0.0, 1.0);
            setup.add_glass(t.p, a * (colour * irradiance + m.emission), glass);
            transmits.resize(glass.size(), (1.0 - a) * (tinted ? colour : glm::dvec3(1.0)));
        }
        // Farthest first (by the mean of 1/w, ties by order): each blends over what lies behind it.
        std::vector<std::size_t> order(glass.size());
        for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
        const auto depth = [&](std::size_t i) { return glass[i].inv_w[0] + glass[i].inv_w[1] + glass[i].inv_w[2]; };
        std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return depth(a) < depth(b); });
        std::vector<ScreenTriangle> sorted_glass;
        std::vector<glm::dvec3> sorted_transmits;
        for (const std::size_t i : order) {
            sorted_glass.push_back(glass[i]);
            sorted_transmits.push_back(transmits[i]);
        }
        glass = std::move(sorted_glass);
        transmits = std::move(sorted_transmits);
    }
    const scene::Dome dome = scene::dome_of(scene);

    // Bin triangles by strip (in order, so z ties resolve the same way in every strip).
    const int strip_samples = kStripRows * kSupersample;
    const int strip_count = (height + kStripRows - 1) / kStripRows;
    const auto bin = [&](const std::vector<ScreenTriangle>& list) {
        std::vector<std::vector<std::uint32_t>> bins(strip_count);
        for (std::size_t i = 0; i < list.size(); ++i) {
            for (int s = list[i].first_row / strip_samples; s <= list[i].last_row / strip_samples; ++s) {
                bins[s].push_back(static_cast<std::uint32_t>(i));
            }
        }
        return bins;
    };
    const std::vector<std::vector<std::uint32_t>> bins = bin(triangles), glass_bins = bin(glass);
    // Strips are independent (each its own rows of the image): on the host's threads.
    parallel::for_each(std::size_t(strip_count), 1, [&](std::size_t s) {
        Strip strip;
        const int rows = std::min(kStripRows, height - int(s) * kStripRows) * kSupersample;
        strip.reset(int(s) * strip_samples, rows, width * kSupersample);
        for (const std::uint32_t i : bins[s]) rasterize(triangles[i], strip);
        if (around.sky) fill_sky(setup, *around.sky, dome, strip);
        for (const std::uint32_t i : glass_bins[s]) blend(glass[i], transmits[i], strip);
        resolve(strip, image);
    });
    return image;
}

}  // namespace hemirad::output
