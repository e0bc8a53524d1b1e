// The Embree ray-casting peer (see embree_engine.h).
#include "formfactor/embree_engine.h"

#include <embree3/rtcore.h>
#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <condition_variable>
#include <exception>
#include <limits>
#include <mutex>
#include <thread>

#include "core/error.h"
#include "formfactor/embree_ray.h"
#include "formfactor/parallel.h"

namespace hemirad::formfactor {

namespace {

constexpr int kPacket = 16;
constexpr int kBlock = 4;  // a packet is a 4×4 block of cells: coherent rays
// The unit of work a thread claims: a tile of 8 × 4 packets (32 × 16 cells) of one face. Small
// enough that N = 64 (24 tiles) keeps every thread busy to the end of a shot, large enough that
// claiming one and handing in its sums cost nothing next to its 512 rays.
constexpr int kTileBlocksU = 8, kTileBlocksV = 4;
constexpr std::size_t kTileCells = std::size_t{kTileBlocksU} * kTileBlocksV * kPacket;
constexpr unsigned kTwinned = 1;  // geometry id of the elements that have a twin (see twin_filter)

// Threads started once and woken per job: a thread started per shot cost as much as the shot
// itself at N = 64. The caller works too, and items are claimed one at a time from a counter,
// so a thread the shared machine slows down holds up only the item it is on.
class ThreadPool {
public:
    explicit ThreadPool(unsigned threads) {
        try {
            for (unsigned t = 1; t < threads; ++t) workers_.emplace_back([this, t] { serve(t); });
        } catch (...) {
            stop();  // none is left running
            throw;
        }
    }
    ~ThreadPool() { stop(); }
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    // Calls job(thread, item) for every item in [0, items), thread 0 being the caller, and
    // returns when all are done; the first exception a job threw is rethrown here.
    template <class Job>
    void run(std::size_t items, Job& job) {
        run(
            items, [](void* j, unsigned t, std::size_t i) { (*static_cast<Job*>(j))(t, i); }, &job);
    }

private:
    using Call = void (*)(void*, unsigned, std::size_t);

    void run(std::size_t items, Call call, void* job) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            call_ = call;
            job_ = job;
            items_ = items;
            next_.store(0, std::memory_order_relaxed);
            error_ = nullptr;
            busy_ = static_cast<unsigned>(workers_.size());
            ++generation_;
        }
        wake_.notify_all();
        drain(0);
        std::unique_lock<std::mutex> lock(mutex_);
        done_.wait(lock, [this] { return busy_ == 0; });
        if (error_) std::rethrow_exception(error_);
    }
    void drain(unsigned t) {
        try {
            for (std::size_t i; (i = next_.fetch_add(1, std::memory_order_relaxed)) < items_;) call_(job_, t, i);
        } catch (...) {
            std::lock_guard<std::mutex> lock(mutex_);
            if (!error_) error_ = std::current_exception();
            next_.store(items_, std::memory_order_relaxed);  // the others stop after their item
        }
    }
    void serve(unsigned t) {
        std::uint64_t seen = 0;
        for (;;) {
            {
                std::unique_lock<std::mutex> lock(mutex_);
                wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
                if (stop_) return;
                seen = generation_;
            }
            drain(t);
            std::lock_guard<std::mutex> lock(mutex_);
            if (--busy_ == 0) done_.notify_one();
        }
    }
    void stop() {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            stop_ = true;
        }
        wake_.notify_all();
        for (auto& w : workers_) w.join();
    }

    std::vector<std::thread> workers_;
    std::mutex mutex_;
    std::condition_variable wake_, done_;
    std::uint64_t generation_ = 0;  // one per run: a worker serves each once
    unsigned busy_ = 0;             // workers not yet done with this run
    bool stop_ = false;
    Call call_ = nullptr;
    void* job_ = nullptr;
    std::size_t items_ = 0;
    std::atomic<std::size_t> next_{0};
    std::exception_ptr error_;
};

}  // namespace

struct EmbreeEngine::Impl {
    // A packet's rays in the hemicube frame and the cells they stand for; 64-byte aligned, as
    // rtcIntersect16 wants its valid mask.
    struct alignas(64) Packet {
        std::array<int, kPacket> valid;             // −1 a cell, 0 past the end of a row
        std::array<float, 3 * kPacket> dir;         // x[16], y[16], z[16], unnormalized
        std::array<std::uint32_t, kPacket> cell{};  // flat index into the delta table
        int size = 0;
    };
    // One shot's frame: floats for the rays, the double origin for the side test.
    struct ShotFrame {
        glm::dvec3 origin{0.0};
        FloatFrame rays;
        const std::vector<double>* table = nullptr;  // the cell weights (Weights) of the shot
    };
    // What one tile of one shot found: sums in the order first hit, and its blocked part.
    struct TileSums {
        std::vector<std::uint32_t> element;
        std::vector<double> F;
        double blocked = 0.0;
    };

    const mesh::Mesh& mesh;
    Settings settings;
    DeltaFormFactors delta;
    std::unique_ptr<DeltaFormFactors> light_delta;  // solid angles, made when a light first shoots
    unsigned threads;
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::vector<std::uint32_t> element_of;  // triangle (first_triangle[geometry] + primID) → element
    std::array<std::uint32_t, 2> first_triangle{};
    float clearance = 0.0f;  // ray_clearance: hits from this height above the shooter's plane on
    std::vector<Packet> packets;          // tile by tile; within a tile, rows of 4×4 blocks
    std::vector<std::size_t> tile_first;  // tile t is packets [tile_first[t], tile_first[t + 1])
    // Kept from batch to batch, so that a shot allocates nothing once a batch of its size ran.
    std::vector<TileSums> tile_sums;  // tile t of the batch's shot b at b × tiles + t
    std::vector<ShotFrame> frames;    // per shot of the batch
    std::vector<std::int32_t> ids;    // the batch's last shot
    std::size_t last_batch = 1;
    // Per thread of the pool: a per-element sum, zero between shots, and the elements it holds
    // (write_result; allocated on a thread's first write).
    mutable std::vector<std::vector<double>> scratch;
    mutable std::vector<std::vector<std::uint32_t>> touched;
    ThreadPool pool;  // last: its threads stop before anything they use goes

    Impl(const mesh::Mesh& m, const Settings& s, unsigned t)
        : mesh(m), settings(s), delta(s.hemicube), threads(t), scratch(t), touched(t), pool(t) {}
    ~Impl() {
        if (scene != nullptr) rtcReleaseScene(scene);
        if (device != nullptr) rtcReleaseDevice(device);
    }
    std::size_t tiles() const { return tile_first.size() - 1; }
    void build();
    void build_packets();
    void run(const ShotRequest* shots, std::size_t count, ShotResult* out);
    // Casts tile `tile` of a shot from `frame` into `sums`, and into ids (element, −1 empty, −2 a
    // blocker) where `ids` is not null.
    void cast_tile(const ShotFrame& frame, std::size_t tile, TileSums& sums, std::int32_t* ids) const;
    bool seen_from_behind(const RTCRayHit16& rh, int r, const ShotFrame& f, std::uint32_t k) const;
    void write_result(unsigned thread, const TileSums* shot_tiles, ShotResult& out) const;
    static void twin_filter(const RTCFilterFunctionNArguments* args);
};

// A twinned element is drawn only from its front: the same surface faces the other way as its
// twin, which takes the hits from behind (as the reference skips the back of a twinned element).
void EmbreeEngine::Impl::twin_filter(const RTCFilterFunctionNArguments* args) {
    const auto* impl = static_cast<const Impl*>(args->geometryUserPtr);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const std::uint32_t k =
            impl->element_of[impl->first_triangle[kTwinned] + RTCHitN_primID(args->hit, args->N, i)];
        const glm::dvec3& n = impl->mesh.elements[k].normal;
        const glm::dvec3 dir{RTCRayN_dir_x(args->ray, args->N, i), RTCRayN_dir_y(args->ray, args->N, i),
                             RTCRayN_dir_z(args->ray, args->N, i)};
        if (glm::dot(n, dir) > 0.0) args->valid[i] = 0;  // seen from behind
    }
}

void EmbreeEngine::Impl::build() {
    // Embree builds the BVH on the engine's thread count; the engine's own threads cast.
    device = rtcNewDevice(fmt::format("threads={}", threads).c_str());
    if (device == nullptr) throw InternalError("embree: rtcNewDevice failed");
    scene = rtcNewScene(device);
    // A static scene, built once and cast at millions of times: the best BVH Embree builds (with
    // spatial splits for triangles). Robust (watertight) triangle tests: the default test is not
    // watertight on an edge two elements share, and in the closed box of tests/test_embree.cpp a
    // ray slipped out between two of them; what that costs is in bench/results/embree.md.
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);

    // Triangles, Embree's fastest primitive: an element is one or, a quad, two (fanned from its
    // first vertex; it is planar and convex, so they cover it exactly), both mapping back to it.
    // One geometry without a filter and one, filtered, for twinned elements.
    for (unsigned g = 0; g < 2; ++g) {
        first_triangle[g] = static_cast<std::uint32_t>(element_of.size());
        std::size_t vertex_count = 0;
        for (std::uint32_t k = 0; k < mesh.elements.size(); ++k) {
            const mesh::Element& e = mesh.elements[k];
            if (e.has_twin != (g == kTwinned)) continue;
            vertex_count += static_cast<std::size_t>(e.poly.n);
            for (int t = 2; t < e.poly.n; ++t) element_of.push_back(k);
        }
        const std::size_t triangles = element_of.size() - first_triangle[g];
        RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
        auto* vertices =
            static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                        3 * sizeof(float), std::max<std::size_t>(1, vertex_count)));
        auto* indices = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
            geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t), triangles));
        if (vertices == nullptr || (indices == nullptr && triangles != 0))
            throw InternalError("embree: geometry buffers could not be allocated");
        std::size_t v = 0, t = 0;
        for (std::uint32_t k = 0; k < mesh.elements.size(); ++k) {
            const mesh::Element& e = mesh.elements[k];
            if (e.has_twin != (g == kTwinned)) continue;
            const auto first = static_cast<std::uint32_t>(v);
            for (int c = 0; c < e.poly.n; ++c, ++v)
                for (int a = 0; a < 3; ++a)
                    vertices[3 * v + static_cast<std::size_t>(a)] =
                        static_cast<float>(e.poly.v[static_cast<std::size_t>(c)][a]);
            for (int c = 2; c < e.poly.n; ++c, ++t) {
                indices[3 * t] = first;
                indices[3 * t + 1] = first + static_cast<std::uint32_t>(c) - 1;
                indices[3 * t + 2] = first + static_cast<std::uint32_t>(c);
            }
        }
        if (g == kTwinned) {
            rtcSetGeometryUserData(geom, this);
            rtcSetGeometryIntersectFilterFunction(geom, twin_filter);
        }
        rtcCommitGeometry(geom);
        const unsigned id = rtcAttachGeometry(scene, geom);
        rtcReleaseGeometry(geom);
        if (id != g) throw InternalError("embree: unexpected geometry id");
    }
    rtcCommitScene(scene);
    if (rtcGetDeviceError(device) != RTC_ERROR_NONE) throw InternalError("embree: the scene did not build");

    clearance = ray_clearance(mesh);
    build_packets();
}

// The cells as packets of 4×4 blocks, grouped into tiles face by face; a tile's packets are
// neighbours, so its rays share most of their path through the BVH.
void EmbreeEngine::Impl::build_packets() {
    const int n = delta.n();
    const double half = 0.5 * n;
    tile_first.assign(1, 0);
    for (int face = 0; face < kFaces; ++face) {
        const double t0 = face == 0 ? 1.0 : 0.0;
        const int rows = delta.rows(face);
        for (int tj = 0; tj < rows; tj += kTileBlocksV * kBlock)
            for (int ti = 0; ti < n; ti += kTileBlocksU * kBlock) {
                for (int bj = tj; bj < std::min(rows, tj + kTileBlocksV * kBlock); bj += kBlock)
                    for (int bi = ti; bi < std::min(n, ti + kTileBlocksU * kBlock); bi += kBlock) {
                        Packet p;
                        p.valid.fill(0);
                        p.dir.fill(0.0f);
                        for (int r = 0; r < kPacket; ++r) p.dir[2 * kPacket + r] = 1.0f;  // unused lanes
                        for (int j = bj; j < std::min(rows, bj + kBlock); ++j)
                            for (int i = bi; i < std::min(n, bi + kBlock); ++i, ++p.size) {
                                const auto r = static_cast<std::size_t>(p.size);
                                const glm::dvec3 d =
                                    from_face(face, {(i + 0.5) / half - 1.0, (j + 0.5) / half - t0, 1.0});
                                p.valid[r] = -1;
                                for (int a = 0; a < 3; ++a) p.dir[a * kPacket + r] = static_cast<float>(d[a]);
                                p.cell[r] = static_cast<std::uint32_t>(delta.offset(face) +
                                                                       static_cast<std::size_t>(j) * n + i);
                            }
                        packets.push_back(p);
                    }
                tile_first.push_back(packets.size());
            }
    }
    ids.assign(delta.cells(), -1);
}

// Which side of element k the ray of lane r met, as the reference decides it: the shooter's
// origin against the element's plane, in doubles. Where the ray crosses the plane at a cosine
// above 0.1 the sign of Embree's normal (counter-clockwise front, as elements are wound) against
// the ray says the same, and the element's data stays out of the cache: the two can differ only
// where the origin lies within float rounding of the plane (~1e-7 of the scene), and at that
// cosine it lies 0.1 of the hit's distance away, a distance the clearance above the shooter's
// plane keeps at 1e-6 of the scene or more.
inline bool EmbreeEngine::Impl::seen_from_behind(const RTCRayHit16& rh, int r, const ShotFrame& f,
                                                 std::uint32_t k) const {
    const float nx = rh.hit.Ng_x[r], ny = rh.hit.Ng_y[r], nz = rh.hit.Ng_z[r];
    const float dx = rh.ray.dir_x[r], dy = rh.ray.dir_y[r], dz = rh.ray.dir_z[r];
    const float cos_nd = nx * dx + ny * dy + nz * dz;  // times |Ng| |d|
    if (cos_nd * cos_nd > 1e-2f * (nx * nx + ny * ny + nz * nz) * (dx * dx + dy * dy + dz * dz)) return cos_nd > 0.0f;
    const mesh::Element& e = mesh.elements[k];
    return glm::dot(e.normal, f.origin - e.centroid) < 0.0;
}

void EmbreeEngine::Impl::cast_tile(const ShotFrame& f, std::size_t tile, TileSums& sums, std::int32_t* ids_out) const {
    const auto& table = *f.table;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    alignas(64) RTCRayHit16 rh;
    double blocked = 0.0;
    sums.element.clear();
    sums.F.clear();
    // Element → its entry in `sums`, by open addressing over twice the tile's cells (never more
    // than half full): it stays in the L1 cache whatever the scene's size, where a dense array
    // over the elements was 4 MB a thread at 1M triangles and a cache miss a hit.
    constexpr std::uint32_t kSlotBits = 10;
    static_assert(std::size_t{1} << kSlotBits >= 2 * kTileCells);
    std::array<std::int32_t, std::size_t{1} << kSlotBits> entry;
    entry.fill(-1);
    const auto entry_of = [&](std::uint32_t k) {
        for (std::uint32_t h = (k * 2654435761u) >> (32 - kSlotBits);; h = (h + 1) & ((1u << kSlotBits) - 1)) {
            const std::int32_t e = entry[h];
            if (e < 0) {
                entry[h] = static_cast<std::int32_t>(sums.element.size());
                sums.element.push_back(k);
                sums.F.push_back(0.0);
                return sums.element.size() - 1;
            }
            if (sums.element[static_cast<std::size_t>(e)] == k) return static_cast<std::size_t>(e);
        }
    };
    // Neighbouring cells mostly hit the same element: the last one's entry is kept at hand.
    std::uint32_t last = std::numeric_limits<std::uint32_t>::max();
    std::size_t last_entry = 0;
    for (std::size_t q = tile_first[tile]; q < tile_first[tile + 1]; ++q) {
        const Packet& p = packets[q];
        for (int r = 0; r < kPacket; ++r) {
            const float x = p.dir[r], y = p.dir[kPacket + r], z = p.dir[2 * kPacket + r];
            set_packet_ray(rh, r, f.rays, x, y, z, clearance);
        }
        rtcIntersect16(p.valid.data(), scene, &context, &rh);
        for (int r = 0; r < p.size; ++r) {
            const std::uint32_t cell = p.cell[static_cast<std::size_t>(r)];
            std::int32_t id = -1;
            if (rh.hit.geomID[r] != RTC_INVALID_GEOMETRY_ID) {
                const std::uint32_t k = element_of[first_triangle[rh.hit.geomID[r]] + rh.hit.primID[r]];
                // The back of a one-sided surface blocks (a twinned one's back was filtered out).
                if (seen_from_behind(rh, r, f, k)) {
                    id = -2;
                    blocked += table[cell];
                } else {
                    id = static_cast<std::int32_t>(k);
                    if (k != last) {
                        last = k;
                        last_entry = entry_of(k);
                    }
                    sums.F[last_entry] += table[cell];
                }
            }
            if (ids_out != nullptr) ids_out[cell] = id;
        }
    }
    sums.blocked = blocked;
}

// The one place a shot's ShotResult is written: its tiles' sums added in tile order, whichever
// thread cast which tile, so the bits do not depend on the thread count.
void EmbreeEngine::Impl::write_result(unsigned thread, const TileSums* shot_tiles, ShotResult& out) const {
    std::vector<double>& sum = scratch.at(thread);
    std::vector<std::uint32_t>& hit = touched.at(thread);
    if (sum.empty()) sum.assign(mesh.elements.size(), 0.0);
    // Tiles added in tile order into a dense scratch (zero between shots), then the row read off
    // the elements touched, ascending: a shot costs its hits, not the mesh.
    out.clear();
    hit.clear();
    for (std::size_t t = 0; t < tiles(); ++t) {
        const TileSums& sums = shot_tiles[t];
        for (std::size_t j = 0; j < sums.element.size(); ++j) {
            const std::uint32_t k = sums.element[j];
            if (sum[k] == 0.0) hit.push_back(k);  // every delta form factor is > 0
            sum[k] += sums.F[j];
        }
        out.blocked += sums.blocked;
    }
    std::sort(hit.begin(), hit.end());
    for (const std::uint32_t k : hit) {
        out.push(k, sum[k]);
        sum[k] = 0.0;
    }
}

void EmbreeEngine::Impl::run(const ShotRequest* shots, std::size_t count, ShotResult* out) {
    if (count == 0) return;
    const std::size_t per_shot = tiles();
    frames.resize(std::max(frames.size(), count));
    for (std::size_t b = 0; b < count; ++b) {
        const Frame frame = make_frame(mesh, shots[b].shooter, settings.seed, shots[b].shot);
        ShotFrame& f = frames[b];
        f.origin = frame.origin;
        f.rays = float_frame(frame);
        const bool light = weights_of(shots[b].shooter) == Weights::solid_angle;
        if (light && !light_delta) light_delta = std::make_unique<DeltaFormFactors>(delta.n(), Weights::solid_angle);
        f.table = light ? &light_delta->table() : &delta.table();
    }
    while (tile_sums.size() < count * per_shot) {
        tile_sums.emplace_back();
        tile_sums.back().element.reserve(kTileCells);  // a tile hits at most one element a ray
        tile_sums.back().F.reserve(kTileCells);
    }
    // Every tile of every shot in one job, shot by shot: a thread done with its last tile of a
    // shot goes on to the next shot's instead of waiting for the others.
    auto cast = [&](unsigned, std::size_t item) {
        const std::size_t b = item / per_shot;
        cast_tile(frames[b], item % per_shot, tile_sums[item], b + 1 == count ? ids.data() : nullptr);
    };
    pool.run(count * per_shot, cast);
    auto write = [&](unsigned thread, std::size_t b) { write_result(thread, &tile_sums[b * per_shot], out[b]); };
    if (count == 1)
        write(0, 0);  // not worth waking the threads for
    else
        pool.run(count, write);
    last_batch = count;
}

EmbreeEngine::EmbreeEngine(const mesh::Mesh& mesh, const Settings& settings, unsigned threads)
    : impl_(std::make_unique<Impl>(mesh, settings,
                                   threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency()))) {
    impl_->build();
}

EmbreeEngine::~EmbreeEngine() = default;

std::string EmbreeEngine::version() {
    return fmt::format("Embree {}.{}.{}", RTC_VERSION_MAJOR, RTC_VERSION_MINOR, RTC_VERSION_PATCH);
}

unsigned EmbreeEngine::threads() const {
    return impl_->threads;
}

void EmbreeEngine::shoot(const ShotRequest& request, ShotResult& out) {
    if (request.shooter.kind == Shooter::Kind::directional) {
        place_.assign(1, -1);
        shoot_directional(impl_->mesh, request, out);
        return;
    }
    place_.clear();
    impl_->run(&request, 1, &out);
}

void EmbreeEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    out.resize(shots.size());
    // Directional lights' parallel shots on the host (no rays: the host's raster), the
    // hemicubes cast together.
    if (!split_directional(shots, hemicubes_, place_)) {
        place_.clear();
        impl_->run(shots.data(), shots.size(), out.data());
        return;
    }
    rows_.resize(hemicubes_.size());
    impl_->run(hemicubes_.data(), hemicubes_.size(), rows_.data());
    for (std::size_t i = 0; i < shots.size(); ++i) {
        if (place_[i] < 0) shoot_directional(impl_->mesh, shots[i], out[i]);
        else out[i] = std::move(rows_[static_cast<std::size_t>(place_[i])]);
    }
}

const std::vector<std::int32_t>* EmbreeEngine::last_ids(std::size_t i) const {
    if (!place_.empty()) {  // a batch with directional shots: the hemicubes' last is kept
        if (i >= place_.size() || place_[i] < 0) return nullptr;
        i = static_cast<std::size_t>(place_[i]);
    }
    return i + 1 == impl_->last_batch ? &impl_->ids : nullptr;
}

}  // namespace hemirad::formfactor
