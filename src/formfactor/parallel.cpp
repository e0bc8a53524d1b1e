// Parallel shots (see parallel.h): project, bin into tiles, draw each tile with a depth test,
// count each element's cells.
#include "formfactor/parallel.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include <fmt/format.h>

#include "core/error.h"
#include "formfactor/hemicube.h"
#include "formfactor/reference.h"

namespace hemirad::formfactor {
namespace {

constexpr double kMaxSlope = 64.0;  // of the centroid test's bias: grazing surfaces are not lit through walls
constexpr std::uint32_t kNoRecord = 0xffffffffu;

// One element as the grid sees it, before it becomes a record: its projected polygon, its plane,
// which gives the depth along the light at a cell's centre, and its centroid.
struct Drawn {
    std::uint32_t element = 0;
    int n = 0;
    double x[4], y[4];
    double nu = 0.0, nv = 0.0, nw = 0.0, c = 0.0;  // n·(x u + y v + z w) = c in the grid's frame
    double cx = 0.0, cy = 0.0, cz = 0.0;           // its centroid in the grid's frame
    bool blocker = false;

    double depth(double x, double y) const { return (c - nu * x - nv * y) / nw; }
    double slope() const { return std::sqrt(nu * nu + nv * nv) / std::abs(nw); }  // |∇ depth|
};

// Record r's depth at the centre of cell (i, j): exactly as kernels/parallel.cl computes it.
double record_depth(const ParallelRecords& r, std::size_t q, int i, int j) {
    const double x = (i + 0.5) * r.grid.cell + r.xmin, y = (j + 0.5) * r.grid.cell + r.ymin;
    return (r.plane[4 * q + 3] - r.plane[4 * q] * x - r.plane[4 * q + 1] * y) / r.plane[4 * q + 2];
}

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

void draw_parallel(const ParallelRecords& records, std::vector<std::int32_t>& owner, std::vector<std::uint32_t>& covered,
                   int threads) {
    const ParallelGrid& grid = records.grid;
    owner.assign(static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height), -1);
    const std::size_t tiles = static_cast<std::size_t>(records.tiles_x) * static_cast<std::size_t>(records.tiles_y);
    const int workers = std::max(1, std::min<int>(threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency()),
                                                  static_cast<int>(std::max<std::size_t>(tiles, 1))));
    // Cell-centre counts per worker, summed after: integers, so in any order.
    std::vector<std::vector<std::uint32_t>> counts(static_cast<std::size_t>(workers),
                                                   std::vector<std::uint32_t>(records.size(), 0));
    std::atomic<std::size_t> next{0};
    const auto work = [&](std::vector<std::uint32_t>& count) {
        constexpr int T = kParallelTile;
        double depth[T * T];
        std::int32_t best[T * T];
        for (std::size_t t; (t = next.fetch_add(1)) < tiles;) {
            const std::uint32_t first = records.bin_start[t], end = records.bin_start[t + 1];
            if (first == end) continue;
            const int ti = static_cast<int>(t % static_cast<std::size_t>(records.tiles_x)) * T;
            const int tj = static_cast<int>(t / static_cast<std::size_t>(records.tiles_x)) * T;
            std::fill(best, best + T * T, -1);
            for (std::uint32_t k = first; k < end; ++k) {
                const std::uint32_t q = records.bin_items[k];
                const std::int32_t* shape = &records.shape[5 * std::size_t(q)];
                const int i0 = std::max(shape[1], ti), i1 = std::min(shape[2], ti + T - 1);
                const int j0 = std::max(shape[3], tj), j1 = std::min(shape[4], tj + T - 1);
                for (int j = j0; j <= j1; ++j)
                    for (int i = i0; i <= i1; ++i) {
                        if (!covers_cell(&records.px[4 * std::size_t(q)], &records.py[4 * std::size_t(q)], shape[0], i, j))
                            continue;
                        ++count[q];
                        const double z = record_depth(records, q, i, j);
                        const int c = (j - tj) * T + (i - ti);
                        if (best[c] < 0 || z < depth[c]) {  // records ascend: a tie keeps the first
                            depth[c] = z;
                            best[c] = static_cast<std::int32_t>(q);
                        }
                    }
            }
            for (int j = tj; j < std::min(tj + T, grid.height); ++j)
                for (int i = ti; i < std::min(ti + T, grid.width); ++i)
                    owner[static_cast<std::size_t>(j) * static_cast<std::size_t>(grid.width) + static_cast<std::size_t>(i)] =
                        best[(j - tj) * T + (i - ti)];
        }
    };
    std::vector<std::thread> pool;
    for (int i = 1; i < workers; ++i) pool.emplace_back(work, std::ref(counts[static_cast<std::size_t>(i)]));
    work(counts[0]);
    for (std::thread& t : pool) t.join();
    covered = std::move(counts[0]);
    for (std::size_t i = 1; i < counts.size(); ++i)
        for (std::size_t q = 0; q < covered.size(); ++q) covered[q] += counts[i][q];
}

ParallelGrid shoot_directional(const mesh::Mesh& mesh, const ShotRequest& request, ShotResult& out,
                               ParallelRaster* raster, std::vector<std::int32_t>* owner) {
    if (request.shooter.kind != Shooter::Kind::directional)
        throw InternalError("parallel shot: the shooter is not a directional light");
    if (request.shooter.patch >= mesh.directions.size())
        throw InternalError(fmt::format("parallel shot: directional light {} of {}", request.shooter.patch,
                                        mesh.directions.size()));
    return shoot_parallel(mesh, mesh.directions[request.shooter.patch].direction, request.shot, out, {}, raster, owner);
}

bool split_directional(const std::vector<ShotRequest>& shots, std::vector<ShotRequest>& hemicubes,
                       std::vector<long>& place) {
    const auto directional = [](const ShotRequest& r) { return r.shooter.kind == Shooter::Kind::directional; };
    if (std::none_of(shots.begin(), shots.end(), directional)) return false;
    hemicubes.clear();
    place.assign(shots.size(), -1);
    for (std::size_t i = 0; i < shots.size(); ++i) {
        if (directional(shots[i])) continue;
        place[i] = static_cast<long>(hemicubes.size());
        hemicubes.push_back(shots[i]);
    }
    return true;
}

ParallelGrid shoot_parallel(const mesh::Mesh& mesh, const glm::dvec3& direction, std::uint64_t shot, ShotResult& out,
                            const ParallelSettings& settings, ParallelRaster* raster,
                            std::vector<std::int32_t>* owner_out) {
    out.clear();
    if (owner_out) owner_out->clear();
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
        for (int i = 0; i < e.poly.n; ++i) {
            const glm::dvec3 local = frame.to_local(e.poly.v[i]);
            d.x[i] = local.x;
            d.y[i] = local.y;
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
    }
    if (drawn.empty()) return grid;

    // The cell: a fraction of the median element's edge, grown where the grid would be too wide.
    const double extent = std::max(xmax - xmin, ymax - ymin);
    double cell = median_edge(mesh) * settings.cell;
    if (!(cell > 0.0) || extent / cell > settings.max_cells - 1) cell = extent / (settings.max_cells - 1);
    if (!(cell > 0.0)) return grid;  // every element edge-on or a point
    grid.cell = cell;
    grid.width = std::min(settings.max_cells, static_cast<int>(std::ceil((xmax - xmin) / cell)) + 1);
    grid.height = std::min(settings.max_cells, static_cast<int>(std::ceil((ymax - ymin) / cell)) + 1);
    // Depths closer than this are one surface (the centroid test below).
    const double tolerance = 1e-9 * std::max({extent, std::abs(xmin), std::abs(xmax), std::abs(ymin), std::abs(ymax)});

    // Records: snapped, counter-clockwise, with their cell boxes, binned by tile.
    ParallelRecords records;
    records.grid = grid;
    records.xmin = xmin;
    records.ymin = ymin;
    records.tiles_x = (grid.width + kParallelTile - 1) / kParallelTile;
    records.tiles_y = (grid.height + kParallelTile - 1) / kParallelTile;
    std::vector<std::uint32_t> record_of(drawn.size(), kNoRecord);
    std::vector<std::uint32_t> drawn_of;  // per record
    for (std::size_t q = 0; q < drawn.size(); ++q) {
        const Drawn& d = drawn[q];
        std::int64_t px[4] = {0, 0, 0, 0}, py[4] = {0, 0, 0, 0};
        for (int i = 0; i < d.n; ++i) {
            px[i] = snap((d.x[i] - xmin) / cell);
            py[i] = snap((d.y[i] - ymin) / cell);
        }
        std::int64_t area2 = 0;
        for (int i = 0; i < d.n; ++i) {
            const int j = (i + 1) % d.n;
            area2 += px[i] * py[j] - px[j] * py[i];
        }
        if (area2 == 0) continue;
        if (area2 < 0) {
            std::reverse(px, px + d.n);
            std::reverse(py, py + d.n);
        }
        const int i0 = std::max(0, first_centre(*std::min_element(px, px + d.n)));
        const int i1 = std::min(grid.width - 1, last_centre(*std::max_element(px, px + d.n)));
        const int j0 = std::max(0, first_centre(*std::min_element(py, py + d.n)));
        const int j1 = std::min(grid.height - 1, last_centre(*std::max_element(py, py + d.n)));
        record_of[q] = static_cast<std::uint32_t>(drawn_of.size());
        drawn_of.push_back(static_cast<std::uint32_t>(q));
        records.px.insert(records.px.end(), px, px + 4);
        records.py.insert(records.py.end(), py, py + 4);
        // An empty box (i0 > i1) holds no centre: the record is only probed (below).
        records.shape.insert(records.shape.end(), {d.n, i0, i1, j0, j1});
        records.plane.insert(records.plane.end(), {d.nu, d.nv, d.nw, d.c});
    }
    // Bins, counted then filled (compressed rows), records ascending within each.
    const std::size_t tiles = static_cast<std::size_t>(records.tiles_x) * static_cast<std::size_t>(records.tiles_y);
    records.bin_start.assign(tiles + 1, 0);
    const auto for_each_tile = [&](std::size_t r, auto fn) {
        const std::int32_t* shape = &records.shape[5 * r];
        if (shape[1] > shape[2] || shape[3] > shape[4]) return;
        for (int ty = shape[3] / kParallelTile; ty <= shape[4] / kParallelTile; ++ty)
            for (int tx = shape[1] / kParallelTile; tx <= shape[2] / kParallelTile; ++tx)
                fn(static_cast<std::size_t>(ty) * static_cast<std::size_t>(records.tiles_x) + static_cast<std::size_t>(tx));
    };
    for (std::size_t r = 0; r < records.size(); ++r) for_each_tile(r, [&](std::size_t t) { ++records.bin_start[t + 1]; });
    for (std::size_t t = 0; t < tiles; ++t) records.bin_start[t + 1] += records.bin_start[t];
    records.bin_items.resize(records.bin_start[tiles]);
    {
        std::vector<std::uint32_t> fill(records.bin_start.begin(), records.bin_start.end() - 1);
        for (std::size_t r = 0; r < records.size(); ++r)
            for_each_tile(r, [&](std::size_t t) { records.bin_items[fill[t]++] = static_cast<std::uint32_t>(r); });
    }

    std::vector<std::int32_t> owner;
    std::vector<std::uint32_t> covered;
    if (raster) {
        raster->draw(records, owner, covered);
    } else {
        draw_parallel(records, owner, covered, settings.threads);
    }
    if (owner.size() != static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height) ||
        covered.size() != records.size())
        throw InternalError("parallel shot: the raster returned buffers of the wrong size");

    // The cells each record won; the blockers' cells are the blocked share.
    std::vector<std::uint64_t> won(records.size(), 0);
    std::uint64_t blocked = 0;
    for (const std::int32_t r : owner) {
        if (r < 0) continue;
        if (static_cast<std::size_t>(r) >= records.size()) throw InternalError("parallel shot: a cell names no record");
        if (drawn[drawn_of[static_cast<std::size_t>(r)]].blocker) ++blocked;
        else ++won[static_cast<std::size_t>(r)];
    }

    // An element's lit share is the share of the cell centres it holds that it won: exact for
    // one in full light or in full shadow at any cell size. One that holds none (smaller than a
    // cell) is lit as its centroid is: the nearest surface over its cell's centre, extended as a
    // plane to the centroid, lies no nearer than it (a shadow map's test). Its own surface, or a
    // neighbour of it, ties; an occluder lies nearer. Planes of a curved surface part within a
    // cell by up to a cell times their slopes: the bias.
    const auto cell_of = [cell](double at, double from, int cells) {
        return std::clamp(static_cast<int>(std::floor((at - from) / cell)), 0, cells - 1);
    };
    for (std::size_t q = 0; q < drawn.size(); ++q) {  // drawn is in element order: the row is ascending
        const Drawn& d = drawn[q];
        const std::uint32_t r = record_of[q];
        if (d.blocker || r == kNoRecord) continue;
        double lit = 0.0;
        if (covered[r] > 0) {
            lit = static_cast<double>(won[r]) / static_cast<double>(covered[r]);
        } else {
            const int i = cell_of(d.cx, xmin, grid.width), j = cell_of(d.cy, ymin, grid.height);
            const std::int32_t o = owner[static_cast<std::size_t>(j) * static_cast<std::size_t>(grid.width) + static_cast<std::size_t>(i)];
            if (o < 0 || static_cast<std::uint32_t>(o) == r) {
                lit = 1.0;
            } else {
                const Drawn& nearest = drawn[drawn_of[static_cast<std::size_t>(o)]];
                const double bias = tolerance + cell * std::min(d.slope() + nearest.slope(), kMaxSlope);
                lit = nearest.depth(d.cx, d.cy) >= d.cz - bias ? 1.0 : 0.0;
            }
        }
        if (lit > 0.0) out.push(d.element, -d.nw * lit);
    }
    out.blocked = static_cast<double>(blocked) * cell * cell;
    if (owner_out) *owner_out = std::move(owner);
    return grid;
}

}  // namespace hemirad::formfactor
