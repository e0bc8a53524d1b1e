// Parallel shots (see parallel.h): project, bin into tiles, draw each tile with a depth test,
// count each element's cells.
#include "formfactor/parallel.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include "core/error.h"
#include "formfactor/hemicube.h"
#include "formfactor/reference.h"

namespace hemirad::formfactor {
namespace {

constexpr int kTile = 128;  // cells per side of a tile, drawn by one thread at a time
constexpr double kMaxSlope = 64.0;  // of the centroid test's bias: grazing surfaces are not lit through walls

// One element as the grid sees it: its snapped polygon (counter-clockwise, kSubcell units per
// cell), its cell box, and its plane, which gives the depth along the light at a cell's centre.
struct Drawn {
    std::uint32_t element = 0;
    int n = 0;
    std::int64_t px[4], py[4];
    int i0 = 0, i1 = -1, j0 = 0, j1 = -1;  // cells whose centres its box holds
    double nu = 0.0, nv = 0.0, nw = 0.0, c = 0.0;  // n·(x u + y v + z w) = c in the grid's frame
    double cx = 0.0, cy = 0.0, cz = 0.0;           // its centroid in the grid's frame
    bool blocker = false;

    double depth(double x, double y) const { return (c - nu * x - nv * y) / nw; }
    double slope() const { return std::sqrt(nu * nu + nv * nv) / std::abs(nw); }  // |∇ depth|
};

// Per element: the cell centres its polygon holds, those of them where it is the nearest, and
// (for elements that hold none) whether its centroid is in the light.
struct Counts {
    std::vector<std::int64_t> covered, won;
    explicit Counts(std::size_t n) : covered(n, 0), won(n + 1, 0) {}
};

std::int64_t snap(double cells) { return static_cast<std::int64_t>(std::floor(cells * kSubcell + 0.5)); }

double median_edge(const mesh::Mesh& mesh) {
    std::vector<double> areas;
    areas.reserve(mesh.elements.size());
    for (const mesh::Element& e : mesh.elements)
        if (!e.coarse && e.area > 0.0) areas.push_back(e.area);
    if (areas.empty()) return 0.0;
    auto mid = areas.begin() + static_cast<std::ptrdiff_t>(areas.size() / 2);
    std::nth_element(areas.begin(), mid, areas.end());
    return std::sqrt(*mid);
}

}  // namespace

ParallelGrid shoot_parallel(const mesh::Mesh& mesh, const glm::dvec3& direction, std::uint64_t shot, ShotResult& out,
                            const ParallelSettings& settings) {
    out.clear();
    const double length = glm::length(direction);
    if (!(std::abs(length - 1.0) < 1e-9)) throw InternalError("parallel shot: the direction must be a unit vector");
    if (settings.max_cells < 2 || settings.max_cells > kMaxHemicube * 2 || !(settings.cell > 0.0))
        throw InternalError("parallel shot: bad grid settings");

    // The grid's frame: w along the light, (u, v) across it, turned by the shot.
    glm::dvec3 lo(HUGE_VAL), hi(-HUGE_VAL);
    for (const mesh::Element& e : mesh.elements)
        if (!e.coarse)
            for (int i = 0; i < e.poly.n; ++i) {
                lo = glm::min(lo, e.poly.v[i]);
                hi = glm::max(hi, e.poly.v[i]);
            }
    ParallelGrid grid;
    if (!(lo.x <= hi.x)) return grid;  // nothing to light
    const Frame frame = make_frame(0.5 * (lo + hi), direction, /*seed=*/0, shot);

    // Project the elements that face the light, or block it.
    std::vector<Drawn> drawn;
    std::vector<std::array<double, 8>> xy;  // their projected vertices, x then y
    double xmin = HUGE_VAL, xmax = -HUGE_VAL, ymin = HUGE_VAL, ymax = -HUGE_VAL;
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        if (e.coarse) continue;
        const double nw = glm::dot(e.normal, frame.w);
        if (nw == 0.0) continue;  // edge-on: covers no area
        const bool back = nw > 0.0;  // the light travels along w: a front faces it where n·w < 0
        if (back && e.has_twin) continue;  // the twin draws this surface from this side
        Drawn d;
        d.element = static_cast<std::uint32_t>(k);
        d.n = e.poly.n;
        d.blocker = back;
        d.nu = glm::dot(e.normal, frame.u);
        d.nv = glm::dot(e.normal, frame.v);
        d.nw = nw;
        std::array<double, 8> p{};
        for (int i = 0; i < e.poly.n; ++i) {
            const glm::dvec3 local = frame.to_local(e.poly.v[i]);
            p[i] = local.x;
            p[4 + i] = local.y;
            xmin = std::min(xmin, local.x);
            xmax = std::max(xmax, local.x);
            ymin = std::min(ymin, local.y);
            ymax = std::max(ymax, local.y);
            if (i == 0) d.c = d.nu * local.x + d.nv * local.y + d.nw * local.z;
        }
        const glm::dvec3 centroid = frame.to_local(e.centroid);
        d.cx = centroid.x;
        d.cy = centroid.y;
        d.cz = centroid.z;
        drawn.push_back(d);
        xy.push_back(p);
    }
    if (drawn.empty()) return grid;

    // The cell: a fraction of the median element's edge, grown where the grid would be too wide.
    const double extent = std::max(xmax - xmin, ymax - ymin);
    double cell = median_edge(mesh) * settings.cell;
    if (!(cell > 0.0) || extent / cell > settings.max_cells - 1) cell = extent / (settings.max_cells - 1);
    if (!(cell > 0.0)) return grid;  // every element edge-on or a point
    grid.cell = cell;
    // Depths closer than this are one surface (the centroid test below).
    const double tolerance = 1e-9 * std::max({extent, xmax - xmin, std::abs(xmin), std::abs(xmax), std::abs(ymin), std::abs(ymax)});
    grid.width = std::min(settings.max_cells, static_cast<int>(std::ceil((xmax - xmin) / cell)) + 1);
    grid.height = std::min(settings.max_cells, static_cast<int>(std::ceil((ymax - ymin) / cell)) + 1);
    const int tiles_x = (grid.width + kTile - 1) / kTile, tiles_y = (grid.height + kTile - 1) / kTile;

    // Snap, orient counter-clockwise, and bin each element into the tiles its cell box meets, and
    // into the probes of the tile that holds its centroid.
    std::vector<std::vector<std::uint32_t>> bins(static_cast<std::size_t>(tiles_x) * tiles_y);
    std::vector<std::vector<std::uint32_t>> probes(bins.size());
    const auto cell_of = [cell](double at, double from, int cells) {
        return std::clamp(static_cast<int>(std::floor((at - from) / cell)), 0, cells - 1);
    };
    for (std::size_t q = 0; q < drawn.size(); ++q) {
        Drawn& d = drawn[q];
        std::int64_t area2 = 0;
        for (int i = 0; i < d.n; ++i) {
            d.px[i] = snap((xy[q][i] - xmin) / cell);
            d.py[i] = snap((xy[q][4 + i] - ymin) / cell);
        }
        for (int i = 0; i < d.n; ++i) {
            const int j = (i + 1) % d.n;
            area2 += d.px[i] * d.py[j] - d.px[j] * d.py[i];
        }
        if (area2 == 0) continue;
        if (!d.blocker) {
            const int ci = cell_of(d.cx, xmin, grid.width), cj = cell_of(d.cy, ymin, grid.height);
            probes[static_cast<std::size_t>(cj / kTile) * tiles_x + ci / kTile].push_back(static_cast<std::uint32_t>(q));
        }
        if (area2 < 0) {
            std::reverse(d.px, d.px + d.n);
            std::reverse(d.py, d.py + d.n);
        }
        const auto first = [](std::int64_t lo) {
            return static_cast<int>(std::ceil(static_cast<double>(lo - kSubcell / 2) / kSubcell));
        };
        const auto last = [](std::int64_t hi) {
            return static_cast<int>(std::floor(static_cast<double>(hi - kSubcell / 2) / kSubcell));
        };
        d.i0 = std::max(0, first(*std::min_element(d.px, d.px + d.n)));
        d.i1 = std::min(grid.width - 1, last(*std::max_element(d.px, d.px + d.n)));
        d.j0 = std::max(0, first(*std::min_element(d.py, d.py + d.n)));
        d.j1 = std::min(grid.height - 1, last(*std::max_element(d.py, d.py + d.n)));
        if (d.i0 > d.i1 || d.j0 > d.j1) continue;
        for (int ty = d.j0 / kTile; ty <= d.j1 / kTile; ++ty)
            for (int tx = d.i0 / kTile; tx <= d.i1 / kTile; ++tx)
                bins[static_cast<std::size_t>(ty) * tiles_x + tx].push_back(static_cast<std::uint32_t>(q));
    }
    xy = {};  // snapped: no longer needed

    // Draw the tiles: per cell the nearest element along the light (the first in mesh order on
    // a tie), then count the cells each element won.
    const int threads = std::max(1, std::min<int>(settings.threads > 0 ? settings.threads
                                                                        : static_cast<int>(std::thread::hardware_concurrency()),
                                                  static_cast<int>(bins.size())));
    std::vector<Counts> counts(static_cast<std::size_t>(threads), Counts(drawn.size()));
    std::vector<char> centroid_lit(drawn.size(), 0);  // each written by the one tile that probes it
    std::atomic<std::size_t> next{0};
    const auto work = [&](Counts& count) {
        std::vector<double> depth(static_cast<std::size_t>(kTile) * kTile);
        std::vector<std::int32_t> owner(depth.size());
        for (std::size_t t; (t = next.fetch_add(1)) < bins.size();) {
            if (bins[t].empty() && probes[t].empty()) continue;
            const int ti = static_cast<int>(t % tiles_x) * kTile, tj = static_cast<int>(t / tiles_x) * kTile;
            std::fill(owner.begin(), owner.end(), -1);
            for (const std::uint32_t q : bins[t]) {
                const Drawn& d = drawn[q];
                const int i0 = std::max(d.i0, ti), i1 = std::min(d.i1, ti + kTile - 1);
                const int j0 = std::max(d.j0, tj), j1 = std::min(d.j1, tj + kTile - 1);
                for (int j = j0; j <= j1; ++j) {
                    const double y = (j + 0.5) * cell + ymin;
                    for (int i = i0; i <= i1; ++i) {
                        if (!covers_cell(d.px, d.py, d.n, i, j)) continue;
                        ++count.covered[q];
                        const double z = d.depth((i + 0.5) * cell + xmin, y);
                        const std::size_t c = static_cast<std::size_t>(j - tj) * kTile + (i - ti);
                        if (owner[c] < 0 || z < depth[c]) {
                            depth[c] = z;
                            owner[c] = static_cast<std::int32_t>(q);
                        }
                    }
                }
            }
            for (const std::int32_t q : owner)
                if (q >= 0) ++count.won[drawn[static_cast<std::size_t>(q)].blocker ? drawn.size() : static_cast<std::size_t>(q)];
            // An element's centroid is in the light where the nearest surface over its cell's
            // centre, extended as a plane to the centroid, lies no nearer than it (a shadow map's
            // test): its own surface, or a neighbour of it, ties, an occluder lies nearer. Planes
            // of a curved surface part within a cell by up to a cell times their slopes: the bias.
            for (const std::uint32_t q : probes[t]) {
                const Drawn& d = drawn[q];
                const int i = cell_of(d.cx, xmin, grid.width), j = cell_of(d.cy, ymin, grid.height);
                const std::int32_t o = owner[static_cast<std::size_t>(j - tj) * kTile + (i - ti)];
                if (o < 0 || static_cast<std::uint32_t>(o) == q) {
                    centroid_lit[q] = 1;
                    continue;
                }
                const Drawn& nearest = drawn[static_cast<std::size_t>(o)];
                const double bias = tolerance + cell * std::min(d.slope() + nearest.slope(), kMaxSlope);
                centroid_lit[q] = nearest.depth(d.cx, d.cy) >= d.cz - bias;
            }
        }
    };
    std::vector<std::thread> pool;
    for (int i = 1; i < threads; ++i) pool.emplace_back(work, std::ref(counts[static_cast<std::size_t>(i)]));
    work(counts[0]);
    for (std::thread& t : pool) t.join();
    Counts& total = counts[0];
    for (std::size_t i = 1; i < counts.size(); ++i)
        for (std::size_t q = 0; q <= drawn.size(); ++q) {
            if (q < drawn.size()) total.covered[q] += counts[i].covered[q];
            total.won[q] += counts[i].won[q];
        }

    // An element's lit share is the share of the cell centres it holds that it won: exact for
    // one in full light or in full shadow at any cell size. One that holds no centre (smaller
    // than a cell) is lit or not as its centroid is.
    for (std::size_t q = 0; q < drawn.size(); ++q) {  // drawn is in element order: the row is ascending
        const Drawn& d = drawn[q];
        if (d.blocker) continue;
        const double lit = total.covered[q] > 0 ? static_cast<double>(total.won[q]) / static_cast<double>(total.covered[q])
                                                : (centroid_lit[q] ? 1.0 : 0.0);
        if (lit > 0.0) out.push(d.element, -d.nw * lit);
    }
    out.blocked = static_cast<double>(total.won[drawn.size()]) * cell * cell;
    return grid;
}

}  // namespace hemirad::formfactor
