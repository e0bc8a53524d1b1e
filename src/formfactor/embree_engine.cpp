// The Embree ray-casting peer (see embree_engine.h).
#include "formfactor/embree_engine.h"

#include <embree3/rtcore.h>
#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <limits>
#include <thread>

#include "core/error.h"

namespace hemirad::formfactor {

namespace {

constexpr int kPacket = 16;
constexpr int kBlock = 4;         // a packet is a 4×4 block of cells: coherent rays
constexpr unsigned kTwinned = 1;  // geometry id of the elements that have a twin (see twin_filter)

}  // namespace

struct EmbreeEngine::Impl {
    const mesh::Mesh& mesh;
    Settings settings;
    DeltaFormFactors delta;
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::array<std::vector<std::uint32_t>, 2> element_of;  // per geometry: primitive → element
    float tnear = 0.0f;
    // Packets: up to 16 cells each (flat indices into the delta table), 4×4 blocks face by face.
    std::vector<std::array<std::uint32_t, kPacket>> packets;
    std::vector<int> packet_size;
    std::vector<glm::dvec3> local_dir;  // per cell, in the hemicube frame (unnormalized)

    Impl(const mesh::Mesh& m, const Settings& s) : mesh(m), settings(s), delta(s.hemicube) {}
    ~Impl() {
        if (scene != nullptr) rtcReleaseScene(scene);
        if (device != nullptr) rtcReleaseDevice(device);
    }
    void build();
    // Casts packets [first, last) of a shot from `frame` into ids (element, −1 empty, −2 a
    // blocker), adding each cell's delta form factor to F (all zero at the start) and listing in
    // `touched` each element it adds to first; returns the blocked part.
    double cast(const Frame& frame, std::size_t first, std::size_t last, std::vector<std::int32_t>& ids,
                std::vector<double>& F, std::vector<std::uint32_t>& touched) const;
    static void twin_filter(const RTCFilterFunctionNArguments* args);
};

// A twinned element is drawn only from its front: the same surface faces the other way as its
// twin, which takes the hits from behind (as the reference skips the back of a twinned element).
void EmbreeEngine::Impl::twin_filter(const RTCFilterFunctionNArguments* args) {
    const auto* impl = static_cast<const Impl*>(args->geometryUserPtr);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const std::uint32_t k = impl->element_of[kTwinned][RTCHitN_primID(args->hit, args->N, i)];
        const glm::dvec3& n = impl->mesh.elements[k].normal;
        const glm::dvec3 dir{RTCRayN_dir_x(args->ray, args->N, i), RTCRayN_dir_y(args->ray, args->N, i),
                             RTCRayN_dir_z(args->ray, args->N, i)};
        if (glm::dot(n, dir) > 0.0) args->valid[i] = 0;  // seen from behind
    }
}

void EmbreeEngine::Impl::build() {
    device = rtcNewDevice("threads=1");  // the engine's own threads cast; Embree builds on one
    if (device == nullptr) throw InternalError("embree: rtcNewDevice failed");
    scene = rtcNewScene(device);
    // Embree's default traversal, not RTC_SCENE_FLAG_ROBUST: on the Cornell box the robust one
    // was ~15% slower for the same agreement with the reference (tests/test_embree.cpp).
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);

    // Quads (a triangle as a quad with its last vertex repeated), one geometry without a
    // filter and one, filtered, for twinned elements.
    for (unsigned g = 0; g < 2; ++g) {
        std::vector<std::uint32_t>& map = element_of[g];
        for (std::uint32_t k = 0; k < mesh.elements.size(); ++k)
            if (mesh.elements[k].has_twin == (g == kTwinned)) map.push_back(k);
        RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);
        auto* vertices =
            static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                        3 * sizeof(float), 4 * std::max<std::size_t>(1, map.size())));
        auto* quads = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
            geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(std::uint32_t), map.size()));
        if (vertices == nullptr || (quads == nullptr && !map.empty()))
            throw InternalError("embree: geometry buffers could not be allocated");
        for (std::size_t q = 0; q < map.size(); ++q) {
            const mesh::Polygon& poly = mesh.elements[map[q]].poly;
            for (int c = 0; c < 4; ++c) {
                const glm::dvec3& p = poly.v[static_cast<std::size_t>(std::min(c, poly.n - 1))];
                for (int a = 0; a < 3; ++a)
                    vertices[12 * q + 3 * static_cast<std::size_t>(c) + a] = static_cast<float>(p[a]);
                quads[4 * q + static_cast<std::size_t>(c)] =
                    static_cast<std::uint32_t>(4 * q) + static_cast<std::uint32_t>(c);
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

    // Hits nearer than this are the shooter's own plane (the reference clips 1e-9 of the scene's
    // extent above it; floats round at ~1e-7 of it).
    tnear = static_cast<float>(1e4 * base_plane_epsilon(mesh));

    const int n = delta.n();
    const double half = 0.5 * n;
    local_dir.resize(delta.cells());
    for (int face = 0; face < kFaces; ++face) {
        const double t0 = face == 0 ? 1.0 : 0.0;
        const int rows = delta.rows(face);
        for (int j = 0; j < rows; ++j)
            for (int i = 0; i < n; ++i)
                local_dir[delta.offset(face) + static_cast<std::size_t>(j) * n + i] =
                    from_face(face, {(i + 0.5) / half - 1.0, (j + 0.5) / half - t0, 1.0});
        for (int bj = 0; bj < rows; bj += kBlock)
            for (int bi = 0; bi < n; bi += kBlock) {
                std::array<std::uint32_t, kPacket> cells{};
                int size = 0;
                for (int j = bj; j < std::min(rows, bj + kBlock); ++j)
                    for (int i = bi; i < std::min(n, bi + kBlock); ++i)
                        cells[static_cast<std::size_t>(size++)] =
                            static_cast<std::uint32_t>(delta.offset(face) + static_cast<std::size_t>(j) * n + i);
                packets.push_back(cells);
                packet_size.push_back(size);
            }
    }
}

double EmbreeEngine::Impl::cast(const Frame& frame, std::size_t first, std::size_t last, std::vector<std::int32_t>& ids,
                                std::vector<double>& F, std::vector<std::uint32_t>& touched) const {
    const auto& table = delta.table();
    double blocked = 0.0;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    for (std::size_t p = first; p < last; ++p) {
        // rtcIntersect16 requires both 64-byte aligned (the valid mask too: not an int's 4).
        alignas(64) RTCRayHit16 rh;
        alignas(64) std::array<int, kPacket> valid{};
        for (int r = 0; r < kPacket; ++r) {
            const bool live = r < packet_size[p];
            valid[static_cast<std::size_t>(r)] = live ? -1 : 0;
            const glm::dvec3 d = live ? local_dir[packets[p][static_cast<std::size_t>(r)]] : glm::dvec3(0, 0, 1);
            const glm::dvec3 world = d.x * frame.u + d.y * frame.v + d.z * frame.w;
            rh.ray.org_x[r] = static_cast<float>(frame.origin.x);
            rh.ray.org_y[r] = static_cast<float>(frame.origin.y);
            rh.ray.org_z[r] = static_cast<float>(frame.origin.z);
            rh.ray.dir_x[r] = static_cast<float>(world.x);
            rh.ray.dir_y[r] = static_cast<float>(world.y);
            rh.ray.dir_z[r] = static_cast<float>(world.z);
            rh.ray.tnear[r] = tnear;
            rh.ray.tfar[r] = std::numeric_limits<float>::infinity();
            rh.ray.time[r] = 0.0f;
            rh.ray.mask[r] = ~0u;
            rh.ray.id[r] = static_cast<unsigned>(r);
            rh.ray.flags[r] = 0;
            rh.hit.geomID[r] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid.data(), scene, &context, &rh);
        for (int r = 0; r < packet_size[p]; ++r) {
            const std::uint32_t cell = packets[p][static_cast<std::size_t>(r)];
            if (rh.hit.geomID[r] == RTC_INVALID_GEOMETRY_ID) {
                ids[cell] = -1;
                continue;
            }
            const std::uint32_t k = element_of[rh.hit.geomID[r]][rh.hit.primID[r]];
            // The back of a one-sided surface blocks (a twinned one's back was filtered out);
            // which side the shooter sees is decided as the reference decides it.
            const mesh::Element& e = mesh.elements[k];
            if (glm::dot(e.normal, frame.origin - e.centroid) < 0.0) {
                ids[cell] = -2;
                blocked += table[cell];
            } else {
                ids[cell] = static_cast<std::int32_t>(k);
                if (F[k] == 0.0) touched.push_back(k);  // every delta form factor is > 0
                F[k] += table[cell];
            }
        }
    }
    return blocked;
}

EmbreeEngine::EmbreeEngine(const mesh::Mesh& mesh, const Settings& settings, unsigned threads)
    : impl_(std::make_unique<Impl>(mesh, settings)),
      threads_(threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency())),
      sums_(threads_, std::vector<double>(mesh.elements.size(), 0.0)),
      touched_(threads_) {
    impl_->build();
}

EmbreeEngine::~EmbreeEngine() = default;

std::string EmbreeEngine::version() {
    return fmt::format("Embree {}.{}.{}", RTC_VERSION_MAJOR, RTC_VERSION_MINOR, RTC_VERSION_PATCH);
}

void EmbreeEngine::shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
    const Frame frame = make_frame(impl_->mesh.patches.at(patch), impl_->settings.seed, shot);
    const std::size_t packets = impl_->packets.size();
    last_batch_ = 1;
    ids_.assign(impl_->delta.cells(), -1);
    // Thread t casts a fixed range of packets into its own sums, kept between shots (zero but
    // where it touched), so a shot's cost follows its cells, not the scene's size.
    std::vector<double> blocked(threads_, 0.0);
    const auto range = [&](unsigned t) { return packets * t / threads_; };
    const auto cast = [&](unsigned t) {
        blocked[t] = impl_->cast(frame, range(t), range(t + 1), ids_, sums_[t], touched_[t]);
    };
    {
        std::vector<std::thread> workers;
        struct JoinAll {  // also when starting a thread throws: none is left running
            std::vector<std::thread>& threads;
            ~JoinAll() {
                for (auto& w : threads)
                    if (w.joinable()) w.join();
            }
        } join_all{workers};
        for (unsigned t = 1; t < threads_; ++t) workers.emplace_back(cast, t);
        cast(0);
    }
    // The threads' sums added in thread order: the same bits run after run.
    std::vector<double> F(impl_->mesh.elements.size(), 0.0);
    out.blocked = 0.0;
    for (unsigned t = 0; t < threads_; ++t) {
        for (std::uint32_t k : touched_[t]) {
            F[k] += sums_[t][k];
            sums_[t][k] = 0.0;
        }
        touched_[t].clear();
        out.blocked += blocked[t];
    }
    out.assign_nonzero(F.data(), F.size(), [](double f) { return f; });
}

}  // namespace hemirad::formfactor
