// Final gather (see final_gather.h).
#include "solve/final_gather.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "core/parallel.h"
#include "formfactor/analytic.h"
#include "mesh/contact.h"
#include "mesh/refine.h"

namespace hemirad::solve {

namespace {

// A hidden vertex's light is never seen, but a triangle from it to a seen vertex (across the edge
// of a box's footprint, of a lamp's outline) would carry its darkness into the light. Each hidden
// vertex takes the mean of its seen neighbours' (along the triangles' edges) instead, ring by ring
// inward; hidden vertices with no seen vertex around them keep their own.
void fill_hidden(const output::WeldedMesh& welded, const std::vector<std::pair<std::uint32_t, std::uint32_t>>& where,
                 const std::vector<char>& hidden, output::VertexLight& out) {
    std::vector<std::vector<char>> state(welded.nodes.size());  // per vertex: 0 seen, 1 hidden, 2 filled
    bool any = false;
    for (std::size_t i = 0; i < where.size(); ++i) {
        if (!hidden[i]) continue;
        auto& node_state = state[where[i].first];
        if (node_state.empty()) node_state.assign(welded.nodes[where[i].first].positions.size(), 0);
        node_state[where[i].second] = 1;
        any = true;
    }
    if (!any) return;
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        std::vector<char>& st = state[n];
        if (st.empty()) continue;
        const output::WeldedNode& node = welded.nodes[n];
        std::vector<std::vector<std::uint32_t>> neighbours(node.positions.size());
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            for (int a = 0; a < 3; ++a) {
                const std::uint32_t u = node.indices[3 * t + a], w = node.indices[3 * t + (a + 1) % 3];
                if (st[u] == 1) neighbours[u].push_back(w);
                if (st[w] == 1) neighbours[w].push_back(u);
            }
        }
        for (bool changed = true; changed;) {
            changed = false;
            std::vector<std::pair<std::uint32_t, std::pair<glm::dvec3, glm::dvec3>>> ring;
            for (std::uint32_t v = 0; v < st.size(); ++v) {
                if (st[v] != 1) continue;
                glm::dvec3 b(0.0), h(0.0);
                int count = 0;
                for (const std::uint32_t u : neighbours[v]) {
                    if (st[u] == 1) continue;
                    b += out.radiosity[n][u];
                    h += out.irradiance[n][u];
                    ++count;
                }
                if (count > 0) ring.push_back({v, {b / double(count), h / double(count)}});
            }
            for (const auto& [v, value] : ring) {  // a ring at a time: the result is independent of order
                out.radiosity[n][v] = value.first;
                out.irradiance[n][v] = value.second;
                st[v] = 2;
                changed = true;
            }
        }
    }
}

// gather_points of one node, appended to `points`.
void node_gather_points(const output::WeldedNode& node, std::vector<mesh::GatherPoint>& points) {
    // Per vertex: the sum of the centroids of the triangles around it, and their count.
    std::vector<glm::dvec3> around(node.positions.size(), glm::dvec3(0.0));
    std::vector<int> count(node.positions.size(), 0);
    for (std::size_t t = 0; t < node.triangle_count(); ++t) {
        const std::uint32_t* v = &node.indices[3 * t];
        const glm::dvec3 c = (node.positions[v[0]] + node.positions[v[1]] + node.positions[v[2]]) / 3.0;
        for (int k = 0; k < 3; ++k) {
            around[v[k]] += c;
            ++count[v[k]];
        }
    }
    // Vertices on an edge of one triangle only: where the surface ends, folds at a crease or
    // meets another node (each side of a crease has its own vertices).
    std::vector<char> rim(node.positions.size(), 0);
    {
        std::vector<std::uint64_t> edges(3 * node.triangle_count());  // (lower, higher) vertex
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            for (int k = 0; k < 3; ++k) {
                std::uint32_t a = node.indices[3 * t + k], b = node.indices[3 * t + (k + 1) % 3];
                if (a > b) std::swap(a, b);
                edges[3 * t + std::size_t(k)] = (std::uint64_t(a) << 32) | b;
            }
        }
        parallel::sort(edges.begin(), edges.end());
        for (std::size_t i = 0; i < edges.size();) {
            std::size_t j = i + 1;
            while (j < edges.size() && edges[j] == edges[i]) ++j;
            if (j - i == 1) rim[edges[i] >> 32] = rim[edges[i] & 0xffffffffu] = 1;
            i = j;
        }
    }
    // On a convex curve the centroids lie behind the surface: a point moved toward them would
    // look out from under its own triangles (of a double-sided surface, at their other side's
    // light: a closed emitting cylinder's outer vertices gathered its inside, twice the lamp).
    // It is raised along the normal onto the plane of every triangle around it that it lies
    // behind (by more than rounding; never on a flat or concave surface).
    std::vector<double> raise(node.positions.size(), 0.0);
    std::vector<glm::dvec3> moved(node.positions.size());
    for (std::size_t v = 0; v < node.positions.size(); ++v) {
        moved[v] = node.positions[v];
        if (count[v] > 0)
            moved[v] += (rim[v] ? kGatherRimInset : kGatherInset) * (around[v] / double(count[v]) - node.positions[v]);
    }
    for (std::size_t t = 0; t < node.triangle_count(); ++t) {
        const std::uint32_t* v = &node.indices[3 * t];
        const glm::dvec3 a = node.positions[v[0]], b = node.positions[v[1]], c = node.positions[v[2]];
        const glm::dvec3 cross = glm::cross(b - a, c - a);
        const double length = glm::length(cross);
        if (!(length > 0.0)) continue;
        const glm::dvec3 n = cross / length;
        const double size = std::max({glm::length(b - a), glm::length(c - b), glm::length(a - c)});
        for (int k = 0; k < 3; ++k) {
            const double behind = -glm::dot(n, moved[v[k]] - node.positions[v[k]]);
            const double facing = glm::dot(n, node.normals[v[k]]);
            if (behind > 1e-9 * size && facing > 0.1) raise[v[k]] = std::max(raise[v[k]], behind / facing);
        }
    }
    for (std::size_t v = 0; v < node.positions.size(); ++v) {
        mesh::GatherPoint p;
        p.position = moved[v] + raise[v] * node.normals[v];
        p.normal = node.normals[v];
        points.push_back(p);
    }
}

}  // namespace

std::vector<mesh::GatherPoint> gather_points(const output::WeldedMesh& welded,
                                             const std::function<bool(std::size_t node)>& gathered) {
    // Each node's points on the host's threads, then in node order.
    std::vector<std::vector<mesh::GatherPoint>> of(welded.nodes.size());
    parallel::for_each(welded.nodes.size(), 1, [&](std::size_t n) {
        if (gathered(n)) node_gather_points(welded.nodes[n], of[n]);
    });
    std::size_t total = 0;
    for (const auto& points : of) total += points.size();
    std::vector<mesh::GatherPoint> points;
    points.reserve(total);
    for (const auto& node_points : of) points.insert(points.end(), node_points.begin(), node_points.end());
    return points;
}

void split_solved(mesh::Mesh& mesh, const std::vector<bool>& split, const mesh::Texturing* texturing,
                  std::initializer_list<std::vector<glm::dvec3>*> radiosities, std::vector<glm::dvec3>& irradiance) {
    for (const std::vector<glm::dvec3>* b : radiosities)
        if (b->size() != mesh.elements.size()) throw InternalError("splitting: the solution does not match the mesh");
    if (irradiance.size() != mesh.elements.size()) throw InternalError("splitting: the solution does not match the mesh");
    mesh::Refined refined = mesh::split_elements(mesh, split, texturing);
    std::vector<glm::dvec3> h(refined.mesh.elements.size());
    for (std::size_t k = 0; k < h.size(); ++k) h[k] = irradiance[refined.origin[k]];
    for (std::vector<glm::dvec3>* radiosity : radiosities) {
        std::vector<glm::dvec3> b(refined.mesh.elements.size());
        for (std::size_t k = 0; k < b.size(); ++k) {
            const std::uint32_t parent = refined.origin[k];
            const mesh::Element& child = refined.mesh.elements[k];
            const mesh::Element& from = mesh.elements[parent];  // E + ρH with the child's own E and ρ
            b[k] = (*radiosity)[parent] + (child.emission - from.emission) + (child.rho - from.rho) * h[k];
        }
        *radiosity = std::move(b);
    }
    mesh = std::move(refined.mesh);
    irradiance = std::move(h);
}

std::size_t grade_contacts(mesh::Mesh& mesh, std::vector<glm::dvec3>& radiosity, std::vector<glm::dvec3>& irradiance,
                           double min_size, const mesh::Texturing* texturing) {
    if (radiosity.size() != mesh.elements.size() || irradiance.size() != mesh.elements.size())
        throw InternalError("contact grading: the solution does not match the mesh");
    const std::vector<bool> marked = mesh::contact_elements(mesh, min_size);
    const std::size_t split = static_cast<std::size_t>(std::count(marked.begin(), marked.end(), true));
    if (split > 0) split_solved(mesh, marked, texturing, {&radiosity}, irradiance);
    return split;
}

VertexMeans element_means(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                          const std::vector<glm::dvec3>& irradiance, const std::vector<glm::dvec3>& direct) {
    std::vector<glm::dvec3> emission(mesh.elements.size()), rho(mesh.elements.size());
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        emission[k] = mesh.elements[k].emission;
        rho[k] = mesh.elements[k].rho;
    }
    VertexMeans means;
    means.emission = output::vertex_values(welded, mesh, emission);
    means.rho = output::vertex_values(welded, mesh, rho);
    means.irradiance = output::vertex_values(welded, mesh, irradiance);
    if (!direct.empty()) means.direct = output::vertex_values(welded, mesh, direct);
    return means;
}

void fill_hidden(const output::WeldedMesh& welded, const std::vector<std::vector<char>>& hidden,
                 output::VertexLight& out) {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> where;
    std::vector<char> marks;
    for (std::size_t n = 0; n < hidden.size() && n < welded.nodes.size(); ++n) {
        for (std::size_t v = 0; v < hidden[n].size(); ++v) {
            if (!hidden[n][v]) continue;
            where.push_back({static_cast<std::uint32_t>(n), static_cast<std::uint32_t>(v)});
            marks.push_back(1);
        }
    }
    fill_hidden(welded, where, marks, out);
}

namespace {

// The outline of elements [first, first + count), cut from one scene face: see drawn_cells.
bool face_outline(const mesh::Mesh& mesh, std::uint32_t first, std::uint32_t count, mesh::Polygon& out) {
    std::vector<glm::dvec3> corners;
    double area = 0.0;
    for (std::uint32_t k = first; k < first + count; ++k) {
        const mesh::Element& e = mesh.elements[k];
        area += e.area;
        for (int i = 0; i < e.poly.n; ++i) corners.push_back(e.poly.v[static_cast<std::size_t>(i)]);
    }
    const auto less = [](const glm::dvec3& a, const glm::dvec3& b) {
        return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
    };
    std::sort(corners.begin(), corners.end(), less);
    std::vector<glm::dvec3> once;
    for (std::size_t i = 0; i < corners.size();) {
        std::size_t j = i + 1;
        while (j < corners.size() && corners[j] == corners[i]) ++j;
        if (j - i == 1) once.push_back(corners[i]);
        i = j;
    }
    if (once.size() != 3 && once.size() != 4) return false;
    // Counter-clockwise about the face's normal: by their angle about the corners' centre.
    const glm::dvec3 normal = mesh.elements[first].normal;
    glm::dvec3 centre(0.0);
    for (const glm::dvec3& c : once) centre += c / double(once.size());
    const glm::dvec3 u = once[0] - centre;
    const glm::dvec3 w = glm::cross(normal, u);
    std::vector<std::pair<double, std::size_t>> order;
    for (std::size_t i = 0; i < once.size(); ++i)
        order.push_back({std::atan2(glm::dot(once[i] - centre, w), glm::dot(once[i] - centre, u)), i});
    std::sort(order.begin(), order.end());
    mesh::Polygon poly;
    poly.n = static_cast<int>(once.size());
    for (std::size_t i = 0; i < once.size(); ++i) poly.v[i] = once[order[i].second];
    // Convex and turning about the normal at every corner, planar, and the elements' area.
    glm::dvec3 newell(0.0);
    double size = 0.0;
    for (int i = 0; i < poly.n; ++i) {
        const glm::dvec3 &a = poly.v[std::size_t(i)], &b = poly.v[std::size_t((i + 1) % poly.n)],
                         &c = poly.v[std::size_t((i + 2) % poly.n)];
        if (!(glm::dot(glm::cross(b - a, c - b), normal) > 0.0)) return false;
        newell += glm::cross(a, b);
        size = std::max(size, glm::length(b - a));
    }
    for (int i = 0; i < poly.n; ++i)
        if (std::abs(glm::dot(poly.v[std::size_t(i)] - poly.v[0], normal)) > 1e-9 * size) return false;
    const double outline = 0.5 * glm::length(newell);
    if (!(std::abs(outline - area) <= 1e-9 * area)) return false;
    out = poly;
    return true;
}

}  // namespace

std::vector<DrawnCell> drawn_cells(const mesh::Mesh& mesh, const mesh::Patch& patch) {
    std::vector<DrawnCell> cells;
    const std::uint32_t end = patch.first_element + patch.element_count;
    if (!patch.cluster() && patch.element_count > 1) {
        cells.push_back({patch.first_element, patch.element_count, patch.poly});
        return cells;
    }
    for (std::uint32_t k = patch.first_element; k < end;) {
        const std::array<std::uint32_t, 2>& source = mesh.elements[k].source;
        std::uint32_t run = k + 1;
        if (source[0] != mesh::kNoSource)
            while (run < end && mesh.elements[run].source == source) ++run;
        DrawnCell cell{k, run - k, mesh.elements[k].poly};
        if (cell.count == 1 || face_outline(mesh, k, cell.count, cell.poly)) {
            cells.push_back(cell);
        } else {
            for (std::uint32_t e = k; e < run; ++e) cells.push_back({e, 1, mesh.elements[e].poly});
        }
        k = run;
    }
    return cells;
}

mesh::Mesh gather_mesh(const mesh::Mesh& mesh) {
    mesh::Mesh out;
    out.lights = mesh.lights;
    out.directions = mesh.directions;
    out.patches.reserve(mesh.patches.size());
    // Each patch's cells on the host's threads, then in patch order.
    std::vector<std::vector<DrawnCell>> cells(mesh.patches.size());
    parallel::for_each(mesh.patches.size(), 64, [&](std::size_t p) { cells[p] = drawn_cells(mesh, mesh.patches[p]); });
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        mesh::Patch q = mesh.patches[p];
        q.first_element = static_cast<std::uint32_t>(out.elements.size());
        const std::uint32_t index = static_cast<std::uint32_t>(out.patches.size());
        for (const DrawnCell& cell : cells[p]) {
            mesh::Element e = mesh.elements[cell.first];  // node, material, sides as its elements'
            if (cell.count > 1 && !q.cluster()) {  // a cell patch: the patch's own
                e.poly = q.poly;
                e.normal = q.normal;
                e.centroid = q.centroid;
                e.area = q.area;
                e.emission = q.emission;
            } else if (cell.count > 1) {  // a cluster's face: its elements' area-weighted means
                glm::dvec3 emission(0.0), centroid(0.0);
                double area = 0.0;
                for (std::uint32_t k = cell.first; k < cell.first + cell.count; ++k) {
                    const mesh::Element& f = mesh.elements[k];
                    emission += f.area * f.emission;
                    centroid += f.area * f.centroid;
                    area += f.area;
                }
                e.poly = cell.poly;
                e.centroid = centroid / area;
                e.area = area;
                e.emission = emission / area;
            }
            e.patch = index;
            out.elements.push_back(e);
            out.drawn_from.push_back(cell.first);
        }
        q.element_count = static_cast<std::uint32_t>(out.elements.size()) - q.first_element;
        out.patches.push_back(q);
    }
    out.drawn_from.push_back(static_cast<std::uint32_t>(mesh.elements.size()));
    return out;
}

bool final_gather(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                  const std::function<bool(std::size_t node)>& gathered, const std::vector<glm::dvec3>& radiosity,
                  const std::vector<glm::dvec3>& irradiance, const std::vector<glm::dvec3>& direct,
                  const mesh::Mesh& drawn, formfactor::Engine& engine, const GatherSettings& settings,
                  output::VertexLight& out) {
    const std::size_t node_count = welded.nodes.size();
    if (radiosity.size() != mesh.elements.size() || irradiance.size() != mesh.elements.size() ||
        (!direct.empty() && direct.size() != mesh.elements.size()) || drawn.patches.size() != mesh.patches.size()) {
        throw InternalError("final gather: the solution, the lights' light or the drawn mesh do not match the mesh");
    }
    const VertexMeans means = element_means(mesh, welded, irradiance, direct);
    const output::VertexValues &e = means.emission, &r = means.rho, &h = means.irradiance, &d = means.direct;
    out.radiosity.assign(node_count, {});
    out.irradiance.assign(node_count, {});
    std::vector<std::pair<std::uint32_t, std::uint32_t>> where;  // point i's node and vertex
    for (std::size_t n = 0; n < node_count; ++n) {
        out.radiosity[n] = welded.nodes[n].radiosity;
        out.irradiance[n] = h[n];
        if (!gathered(n)) continue;
        for (std::size_t v = 0; v < welded.nodes[n].positions.size(); ++v)
            where.push_back({static_cast<std::uint32_t>(n), static_cast<std::uint32_t>(v)});
    }
    const std::size_t total = where.size();
    if (drawn.drawn_from.size() != drawn.elements.size() + 1 || drawn.drawn_from.back() != mesh.elements.size())
        throw InternalError("final gather: the drawn mesh is not gather_mesh's of the solved mesh");
    if (total != drawn.gather_points.size()) {
        throw InternalError("final gather: the drawn mesh's gather points are not the welded mesh's vertices");
    }

    // What the gather draws: per element of the solved mesh, its radiosity (the solver's, then the
    // last pass's), and per drawn element the area-weighted mean of the elements it stands for.
    std::vector<glm::dvec3> fine = radiosity, coarse(drawn.elements.size(), glm::dvec3(0.0));
    const auto draw = [&] {
        parallel::for_each(drawn.elements.size(), 1024, [&](std::size_t c) {
            const std::uint32_t first = drawn.drawn_from[c], end = drawn.drawn_from[c + 1];
            if (end - first == 1) {  // an element drawn as it is
                coarse[c] = fine[first];
                return;
            }
            glm::dvec3 sum(0.0);
            double area = 0.0;
            for (std::uint32_t k = first; k < end; ++k) {
                sum += mesh.elements[k].area * fine[k];
                area += mesh.elements[k].area;
            }
            coarse[c] = area > 0.0 ? sum / area : glm::dvec3(0.0);
        });
    };
    // A drawn cell close to the point: its elements weighed by their exact unoccluded form factors
    // from the point (the cell's visible form factor, the hemicube's, shared out by them). Returns
    // false for a cell that is one element; else appends the elements' weights (those > 0, in order).
    constexpr double kNearPatches = 2.0;
    struct NearWeight {
        std::uint32_t element;
        double f;
    };
    const auto near_weights = [&](const mesh::GatherPoint& point, std::uint32_t c, std::vector<NearWeight>& into) {
        const std::uint32_t first = drawn.drawn_from[c], end = drawn.drawn_from[c + 1];
        if (end - first <= 1) return false;
        const mesh::Element& cell = drawn.elements[c];
        const double reach = kNearPatches * std::sqrt(cell.area);
        const glm::dvec3 to = point.position - cell.centroid;
        if (glm::dot(to, to) > reach * reach) return false;
        for (std::uint32_t k = first; k < end; ++k) {
            const double f = formfactor::point_to_polygon(point.position, point.normal, mesh.elements[k].poly);
            if (f > 0.0) into.push_back({k, f});
        }
        return true;
    };
    const auto weighed = [&](const NearWeight* w, std::size_t count, std::uint32_t c) {
        glm::dvec3 sum(0.0);
        double weight = 0.0;
        for (std::size_t i = 0; i < count; ++i) {
            sum += w[i].f * fine[w[i].element];
            weight += w[i].f;
        }
        return weight > 0.0 ? sum / weight : coarse[c];
    };

    // A point that sees mostly the backs of one-sided surfaces lies where nothing is seen.
    constexpr double kHiddenBlocked = 0.5;
    std::vector<char> hidden(total, 0);
    const int passes = std::max(1, settings.passes);
    // The light does not depend on the batching (rows are kept in order from the first): as many
    // points as the engine likes in flight.
    const std::size_t batch = engine.batch_for(settings.batch, settings.engine_batch);
    std::vector<formfactor::ShotRequest> requests;
    std::vector<formfactor::ShotResult> results;
    // The first pass's rows, kept for the later passes: the same point, frame and drawn mesh give
    // the same row, so only the radiosities they weigh change. Rows of points [0, kept) in order
    // (compressed, start[i] to start[i + 1]), with their near cells' weights (near_row[i] to
    // near_row[i + 1] index near_at, the entry in the row, and near_start, its weights in
    // near_weight), up to settings.kept_entries entries and weights together; the points past
    // those are shot again. The later passes add the same terms in the same order: the light of
    // shooting again, bit for bit.
    std::vector<std::size_t> start{0}, near_row{0}, near_start{0};
    std::vector<std::uint32_t> kept_element, near_at;
    std::vector<double> kept_F;
    std::vector<NearWeight> near_weight;
    std::size_t kept = 0;
    const auto store = [&](std::size_t i, const glm::dvec3& gathered) {
        const auto [n, v] = where[i];
        const glm::dvec3 light = direct.empty() ? gathered : gathered + d[n][v];
        out.irradiance[n][v] = light;
        out.radiosity[n][v] = e[n][v] + r[n][v] * light;
    };
    // A shot row's light; `near`, when given, gets the near cells' entries in the row and their
    // weights (kept rows' weights, see above). Rows are independent: a batch's are taken on the
    // host's threads, each with its own scratch.
    struct RowNear {
        std::vector<std::uint32_t> at;
        std::vector<std::size_t> end;  // the weights of entry at[q] end at end[q]
        std::vector<NearWeight> weights;
    };
    const auto shot_light = [&](std::size_t i, const formfactor::ShotResult& row, RowNear* near) {
        const mesh::GatherPoint& point = drawn.gather_points[i];
        std::vector<NearWeight> scratch;
        glm::dvec3 light(0.0);
        for (std::size_t k = 0; k < row.size(); ++k) {
            scratch.clear();
            if (!near_weights(point, row.element[k], scratch)) {
                light += row.F[k] * coarse[row.element[k]];
                continue;
            }
            light += row.F[k] * weighed(scratch.data(), scratch.size(), row.element[k]);
            if (near) {
                near->at.push_back(static_cast<std::uint32_t>(k));
                near->weights.insert(near->weights.end(), scratch.begin(), scratch.end());
                near->end.push_back(near->weights.size());
            }
        }
        return light;
    };
    // Kept row i's light.
    const auto kept_light = [&](std::size_t i) {
        const std::uint32_t* element = kept_element.data() + start[i];  // (data() + start: a row may be empty)
        const double* F = kept_F.data() + start[i];
        std::size_t q = near_row[i];
        glm::dvec3 light(0.0);
        for (std::size_t k = 0; k < start[i + 1] - start[i]; ++k) {
            if (q < near_row[i + 1] && near_at[q] == k) {
                light += F[k] * weighed(near_weight.data() + near_start[q], near_start[q + 1] - near_start[q], element[k]);
                ++q;
            } else {
                light += F[k] * coarse[element[k]];
            }
        }
        return light;
    };
    // Known points keep their light and are not shot (settings.known); the rest, in order.
    std::vector<std::uint32_t> todo;
    if (settings.known) {
        if (passes != 1 || !settings.prior) throw InternalError("final gather: known vertices need their light and one pass");
        for (std::size_t i = 0; i < total; ++i) {
            const auto [n, v] = where[i];
            if ((*settings.known)[n][v]) {
                out.radiosity[n][v] = settings.prior->radiosity[n][v];
                out.irradiance[n][v] = settings.prior->irradiance[n][v];
            } else {
                todo.push_back(static_cast<std::uint32_t>(i));
            }
        }
    } else {
        todo.resize(total);
        for (std::size_t i = 0; i < total; ++i) todo[i] = static_cast<std::uint32_t>(i);
    }
    long done = 0;
    const long work = static_cast<long>(todo.size()) * passes;
    for (int pass = 0; pass < passes; ++pass) {
        if (pass > 0) fine = vertex_means(mesh, welded, gathered, out.radiosity, fine);  // from the last pass's vertices
        draw();
        if (pass > 0) {
            if (settings.cancelled && settings.cancelled()) return false;
            parallel::for_each(kept, 64, [&](std::size_t i) { store(i, kept_light(i)); });
            done += static_cast<long>(kept);
            if (settings.progress) settings.progress(done, work);
        }
        // Pass 0 shoots every point to do; the later ones those past the kept rows.
        const std::size_t from = pass > 0 ? kept : 0;
        std::vector<glm::dvec3> light;
        std::vector<RowNear> nears;
        for (std::size_t first = from; first < todo.size(); first += batch) {
            if (settings.cancelled && settings.cancelled()) return false;
            const std::size_t count = std::min(batch, todo.size() - first);
            requests.clear();
            for (std::size_t j = first; j < first + count; ++j)
                requests.push_back(formfactor::ShotRequest::of_point(todo[j], kGatherShots + todo[j]));
            engine.shoot_batch(requests, results);
            // Rows are kept in order from the first while they fit: this batch's may be kept only
            // if its first row is next.
            const bool may_keep = pass == 0 && passes > 1 && kept == todo[first];
            light.assign(count, glm::dvec3(0.0));
            nears.assign(may_keep ? count : 0, RowNear{});
            parallel::for_each(count, 4, [&](std::size_t j) {
                light[j] = shot_light(todo[first + j], results[j], may_keep ? &nears[j] : nullptr);
            });
            for (std::size_t j = 0; j < count; ++j) {
                const formfactor::ShotResult& row = results[j];
                const std::size_t i = todo[first + j];
                store(i, light[j]);
                hidden[i] = row.blocked > kHiddenBlocked;
                if (!may_keep || kept != i) continue;
                const RowNear& near = nears[j];
                if (kept_F.size() + row.size() + near_weight.size() + near_at.size() + near.weights.size() +
                        near.at.size() <=
                    settings.kept_entries) {
                    kept_element.insert(kept_element.end(), row.element.begin(), row.element.end());
                    kept_F.insert(kept_F.end(), row.F.begin(), row.F.end());
                    start.push_back(kept_F.size());
                    const std::size_t base = near_weight.size();
                    near_at.insert(near_at.end(), near.at.begin(), near.at.end());
                    near_weight.insert(near_weight.end(), near.weights.begin(), near.weights.end());
                    for (const std::size_t end : near.end) near_start.push_back(base + end);
                    near_row.push_back(near_at.size());
                    ++kept;
                }  // else past the budget: the rest are shot again
            }
            done += static_cast<long>(count);
            if (settings.progress) settings.progress(done, work);
        }
        fill_hidden(welded, where, hidden, out);
    }
    if (settings.hidden) {
        settings.hidden->resize(node_count);
        for (std::size_t i = 0; i < total; ++i) {
            if (!hidden[i]) continue;
            const auto [n, v] = where[i];
            auto& marks = (*settings.hidden)[n];
            if (marks.empty()) marks.assign(welded.nodes[n].positions.size(), 0);
            marks[v] = 1;
        }
    }
    return true;
}

std::vector<glm::dvec3> vertex_means(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                                     const std::function<bool(std::size_t node)>& gathered,
                                     const output::VertexValues& values, const std::vector<glm::dvec3>& fallback) {
    std::vector<glm::dvec3> sum(mesh.elements.size(), glm::dvec3(0.0));
    std::vector<double> area(mesh.elements.size(), 0.0);
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (!gathered(n)) continue;
        const output::WeldedNode& node = welded.nodes[n];
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            const std::uint32_t* v = &node.indices[3 * t];
            const glm::dvec3 a = node.positions[v[0]], b = node.positions[v[1]], c = node.positions[v[2]];
            const double at = 0.5 * glm::length(glm::cross(b - a, c - a));
            sum[node.element[t]] += at * (values[n][v[0]] + values[n][v[1]] + values[n][v[2]]) / 3.0;
            area[node.element[t]] += at;
        }
    }
    std::vector<glm::dvec3> out = fallback;
    for (std::size_t k = 0; k < out.size(); ++k)
        if (area[k] > 0.0) out[k] = sum[k] / area[k];
    return out;
}

std::vector<bool> gather_contrasts(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                                   const std::function<bool(std::size_t node)>& gathered,
                                   const output::VertexLight& light, double contrast, double noise_floor,
                                   double min_size, std::vector<double>* scores) {
    const auto luminance = [](const glm::dvec3& c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; };
    double mean = 0.0;
    std::size_t count = 0;
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (!gathered(n)) continue;
        for (const glm::dvec3& h : light.irradiance[n]) mean += luminance(h);
        count += light.irradiance[n].size();
    }
    if (scores) scores->assign(mesh.elements.size(), 0.0);
    if (count == 0) return std::vector<bool>(mesh.elements.size(), false);
    const double floor = noise_floor * mean / double(count);
    // Per element, the least and the most of its vertices' light.
    std::vector<double> least(mesh.elements.size(), std::numeric_limits<double>::infinity());
    std::vector<double> most(mesh.elements.size(), -std::numeric_limits<double>::infinity());
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (!gathered(n)) continue;
        const output::WeldedNode& node = welded.nodes[n];
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            const std::uint32_t k = node.element[t];
            for (int a = 0; a < 3; ++a) {
                const double l = luminance(light.irradiance[n][node.indices[3 * t + a]]);
                least[k] = std::min(least[k], l);
                most[k] = std::max(most[k], l);
            }
        }
    }
    std::vector<bool> marked(mesh.elements.size(), false);
    for (std::size_t k = 0; k < marked.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        const double span = most[k] - least[k], rho = luminance(e.rho);
        // What the light changes is ρH against the element's brightest E + ρH: an emitter's own
        // light (a lamp lit unevenly by the room) or a black surface shows no difference.
        if (!(most[k] >= least[k])) continue;  // no gathered vertex
        const double brightest = luminance(e.emission) + rho * most[k];
        marked[k] = rho * span > contrast * brightest && span > floor && mesh::longest_edge(e.poly) > min_size;
        if (scores) (*scores)[k] = brightest > 0.0 ? rho * span / brightest : 0.0;
    }
    return marked;
}

void carry_light(const output::WeldedMesh& old_welded, const output::VertexLight& old_light,
                 const output::WeldedMesh& welded, output::VertexLight& prior,
                 std::vector<std::vector<char>>& known) {
    const double crease_cos = std::cos(mesh::kCreaseAngle);
    const std::size_t node_count = welded.nodes.size();
    prior.radiosity.assign(node_count, {});
    prior.irradiance.assign(node_count, {});
    known.assign(node_count, {});
    for (std::size_t n = 0; n < node_count; ++n) {
        const output::WeldedNode& node = welded.nodes[n];
        prior.radiosity[n].assign(node.positions.size(), glm::dvec3(0.0));
        prior.irradiance[n].assign(node.positions.size(), glm::dvec3(0.0));
        known[n].assign(node.positions.size(), 0);
        if (n >= old_welded.nodes.size() || old_light.radiosity[n].empty()) continue;
        const output::WeldedNode& old = old_welded.nodes[n];
        // Old vertices by position (bit for bit: splitting keeps every corner where it was).
        std::unordered_multimap<std::uint64_t, std::uint32_t> at;
        const auto key = [](const glm::dvec3& p) {
            std::uint64_t h = 0;
            for (int c = 0; c < 3; ++c) {
                const double v = p[c] + 0.0;  // −0 and +0 alike
                std::uint64_t b = 0;
                std::memcpy(&b, &v, sizeof b);
                h = (h ^ b) * 0x9E3779B97F4A7C15ull + (h >> 29);
            }
            return h;
        };
        for (std::uint32_t v = 0; v < old.positions.size(); ++v) at.emplace(key(old.positions[v]), v);
        for (std::uint32_t v = 0; v < node.positions.size(); ++v) {
            const auto [first, last] = at.equal_range(key(node.positions[v]));
            for (auto it = first; it != last; ++it) {
                const std::uint32_t o = it->second;
                if (old.positions[o] != node.positions[v] || glm::dot(old.normals[o], node.normals[v]) < crease_cos)
                    continue;
                // The same side: a double-sided surface's back has its own vertices, facing away.
                prior.radiosity[n][v] = old_light.radiosity[n][o];
                prior.irradiance[n][v] = old_light.irradiance[n][o];
                known[n][v] = 1;
                break;
            }
        }
    }
}

GatherRefined refine_gather(const GatheredMesh& g, const std::function<bool(std::size_t node)>& gathered,
                            const GatherSettings& settings, const GatherRefinement& r) {
    GatherRefined result;
    if (!g.direct.empty() && !r.direct_light) throw InternalError("gather refinement: no way to light a refined mesh");
    const std::size_t node_count = g.welded.nodes.size();
    for (int level = 0; level < r.levels; ++level) {
        std::vector<double> scores;
        std::vector<bool> marked =
            gather_contrasts(g.mesh, g.welded, gathered, g.light, r.contrast, r.noise_floor, r.min_size, &scores);
        std::size_t split = static_cast<std::size_t>(std::count(marked.begin(), marked.end(), true));
        if (split == 0) break;
        const auto gathered_vertices = [&](const output::WeldedMesh& w) {
            std::size_t vertices = 0;
            for (std::size_t n = 0; n < node_count; ++n)
                if (gathered(n)) vertices += w.nodes[n].positions.size();
            return vertices;
        };
        const std::size_t before = gathered_vertices(g.welded);
        mesh::Mesh finer;
        std::vector<glm::dvec3> radiosity, irradiance, drawn_light;
        output::WeldedMesh finer_welded;
        // Past max_vertices, only the elements of the highest contrast, as many as fit (the count
        // scaled down by the vertices over, until it fits); then no further level.
        for (;;) {
            finer = g.mesh;
            radiosity = g.radiosity;
            irradiance = g.irradiance;
            drawn_light = vertex_means(g.mesh, g.welded, gathered, g.light.radiosity, g.radiosity);
            split_solved(finer, marked, r.texturing, {&radiosity, &drawn_light}, irradiance);
            finer_welded = output::weld(node_count, finer, radiosity);
            const std::size_t vertices = gathered_vertices(finer_welded);
            if (vertices <= r.max_vertices) break;
            result.capped = true;
            const double room = r.max_vertices > before ? double(r.max_vertices - before) : 0.0;
            const std::size_t keep =
                static_cast<std::size_t>(double(split) * room / double(vertices - before) * 0.9);
            if (keep == 0) {
                split = 0;
                break;
            }
            std::vector<std::uint32_t> order;
            for (std::uint32_t k = 0; k < marked.size(); ++k)
                if (marked[k]) order.push_back(k);
            std::stable_sort(order.begin(), order.end(),
                             [&](std::uint32_t a, std::uint32_t b) { return scores[a] > scores[b]; });
            for (std::size_t i = keep; i < order.size(); ++i) marked[order[i]] = false;
            split = keep;
        }
        if (split == 0) break;
        output::VertexLight prior;
        std::vector<std::vector<char>> known;
        carry_light(g.welded, g.light, finer_welded, prior, known);
        std::vector<glm::dvec3> direct;
        if (!g.direct.empty()) direct = r.direct_light(finer);
        mesh::Mesh drawn = gather_mesh(finer);
        drawn.gather_points = gather_points(finer_welded, gathered);
        std::unique_ptr<formfactor::Engine> engine = r.make_engine(drawn);
        GatherSettings one = settings;
        one.passes = 1;
        one.known = &known;
        one.prior = &prior;
        output::VertexLight light;
        if (!final_gather(finer, finer_welded, gathered, drawn_light, irradiance, direct, drawn, *engine, one, light)) {
            result.cancelled = true;
            break;
        }
        std::size_t carried = 0;
        for (std::size_t n = 0; n < node_count; ++n)
            if (gathered(n)) carried += static_cast<std::size_t>(std::count(known[n].begin(), known[n].end(), 1));
        result.points += static_cast<long>(drawn.gather_points.size() - carried);
        result.split += split;
        ++result.levels;
        g.mesh = std::move(finer);
        g.radiosity = std::move(radiosity);
        g.irradiance = std::move(irradiance);
        g.direct = std::move(direct);
        g.welded = std::move(finer_welded);
        g.light = std::move(light);
        if (result.capped) break;
    }
    return result;
}

}  // namespace hemirad::solve
