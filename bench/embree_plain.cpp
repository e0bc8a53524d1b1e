// The Embree peer against a plain rtcIntersect16 loop over the same scene, shots and rays: the
// share of Embree's own ray-casting speed that the peer keeps once it sums form factors, keeps an
// id buffer and shares the work among its threads.
// Usage: hemirad_bench_embree SCENE... [--hemicube N,...] [--shots K] [--repeats R] [--batch K]
//                             [--threads T] [--json FILE]
#include <embree3/rtcore.h>
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <fstream>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include "bench/throughput.h"
#include "core/timing.h"
#include "formfactor/embree_engine.h"
#include "formfactor/embree_ray.h"
#include "formfactor/hemicube.h"
#include "mesh/mesh.h"

using namespace hemirad;

namespace {

constexpr int kPacket = 16;
constexpr int kBlock = 4;           // a packet is a 4×4 block of cells, as the peer casts them
constexpr std::size_t kClaim = 16;  // packets a thread claims at a time: few atomics, even ends

// The loop's own scene: every element as one triangle or two, one geometry, no filter, built as
// the peer builds its own (high quality, static; robust, or with Embree's faster default test
// that is not watertight). Twinned elements are not filtered here: that only makes the loop
// faster, and the procedural scenes have none.
class PlainScene {
public:
    PlainScene(const mesh::Mesh& m, RTCSceneFlags flags) : device_(rtcNewDevice(nullptr)) {
        if (device_ == nullptr) throw std::runtime_error("embree: rtcNewDevice failed");
        scene_ = rtcNewScene(device_);
        rtcSetSceneFlags(scene_, flags);
        rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
        std::size_t triangles = 0;
        for (const mesh::Element& e : m.elements) triangles += e.poly.n == 4 ? 2 : 1;
        RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
        auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                     3 * sizeof(float), 4 * m.elements.size()));
        auto* indices = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
            geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t), triangles));
        std::size_t t = 0;
        for (std::size_t k = 0; k < m.elements.size(); ++k) {
            const mesh::Polygon& poly = m.elements[k].poly;
            for (int c = 0; c < 4; ++c)
                for (int a = 0; a < 3; ++a)
                    vertices[12 * k + 3 * static_cast<std::size_t>(c) + a] =
                        static_cast<float>(poly.v[static_cast<std::size_t>(std::min(c, poly.n - 1))][a]);
            const auto v0 = static_cast<std::uint32_t>(4 * k);
            for (int tri = 0; tri + 2 < poly.n; ++tri) {
                indices[3 * t] = v0;
                indices[3 * t + 1] = v0 + static_cast<std::uint32_t>(tri) + 1;
                indices[3 * t + 2] = v0 + static_cast<std::uint32_t>(tri) + 2;
                ++t;
            }
        }
        rtcCommitGeometry(geom);
        rtcAttachGeometry(scene_, geom);
        rtcReleaseGeometry(geom);
        rtcCommitScene(scene_);
        if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw std::runtime_error("embree: the scene did not build");
    }
    ~PlainScene() {
        rtcReleaseScene(scene_);
        rtcReleaseDevice(device_);
    }
    PlainScene(const PlainScene&) = delete;
    PlainScene& operator=(const PlainScene&) = delete;
    RTCScene scene() const { return scene_; }

private:
    RTCDevice device_;
    RTCScene scene_ = nullptr;
};

// One N's rays in the hemicube frame, packet by packet: 4×4 blocks face by face, unnormalized
// directions through the cell centres, unused lanes of a packet at the end of a row masked off.
struct Packets {
    std::vector<std::array<float, 3 * kPacket>> dir;  // x[16], y[16], z[16]
    std::vector<int> lanes;                           // per packet: cells in it (16 but at the end of a short row)
};

Packets make_packets(int n) {
    const formfactor::DeltaFormFactors delta(n);
    const double half = 0.5 * n;
    Packets out;
    for (int face = 0; face < formfactor::kFaces; ++face) {
        const double t0 = face == 0 ? 1.0 : 0.0;
        const int rows = delta.rows(face);
        for (int bj = 0; bj < rows; bj += kBlock)
            for (int bi = 0; bi < n; bi += kBlock) {
                std::array<float, 3 * kPacket> d{};
                int size = 0;
                for (int j = bj; j < std::min(rows, bj + kBlock); ++j)
                    for (int i = bi; i < std::min(n, bi + kBlock); ++i, ++size) {
                        const glm::dvec3 l =
                            formfactor::from_face(face, {(i + 0.5) / half - 1.0, (j + 0.5) / half - t0, 1.0});
                        for (int a = 0; a < 3; ++a)
                            d[static_cast<std::size_t>(a * kPacket + size)] = static_cast<float>(l[a]);
                    }
                out.dir.push_back(d);
                out.lanes.push_back(size);
            }
    }
    return out;
}

// Casts every packet of every shot once on `threads` threads, each claiming packets from one
// counter; nothing is done with a hit but count it (a closed scene must hit with every ray).
std::size_t plain_loop(RTCScene scene, const Packets& packets, const std::vector<formfactor::FloatFrame>& frames,
                       float clearance, unsigned threads) {
    const std::size_t per_shot = packets.dir.size(), total = per_shot * frames.size();
    std::atomic<std::size_t> next{0};
    std::vector<std::size_t> hits(threads, 0);
    const auto work = [&](unsigned t) {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        alignas(64) RTCRayHit16 rh;
        alignas(64) std::array<int, kPacket> valid{};
        std::size_t count = 0;
        for (std::size_t first; (first = next.fetch_add(kClaim)) < total;)
            for (std::size_t p = first; p < std::min(total, first + kClaim); ++p) {
                const formfactor::FloatFrame& f = frames[p / per_shot];
                const std::size_t q = p % per_shot;
                const auto& d = packets.dir[q];
                for (int r = 0; r < kPacket; ++r) {
                    const float x = d[r], y = d[kPacket + r], z = d[2 * kPacket + r];
                    valid[static_cast<std::size_t>(r)] = r < packets.lanes[q] ? -1 : 0;
                    set_packet_ray(rh, r, f, x, y, z, clearance);
                }
                rtcIntersect16(valid.data(), scene, &context, &rh);
                for (int r = 0; r < packets.lanes[q]; ++r) count += rh.hit.geomID[r] != RTC_INVALID_GEOMETRY_ID;
            }
        hits[t] = count;
    };
    std::vector<std::thread> workers;
    for (unsigned t = 1; t < threads; ++t) workers.emplace_back(work, t);
    work(0);
    for (auto& w : workers) w.join();
    std::size_t sum = 0;
    for (std::size_t h : hits) sum += h;
    return sum;
}

}  // namespace

int main(int argc, char** argv) {
    bench::ThroughputOptions o;
    o.hemicubes = {64, 256, 1024};
    o.shots = 16;
    o.repeats = 3;
    unsigned threads = std::max(1u, std::thread::hardware_concurrency());
    std::string json_path;
    int batch_size = 1;  // shots per shoot_batch call of the peer
    CLI::App app{"the Embree peer against a plain rtcIntersect16 loop over the same rays"};
    app.add_option("scenes", o.scenes, "glTF files or procedural:<triangles>")->required();
    app.add_option("--hemicube", o.hemicubes)->delimiter(',')->capture_default_str();
    app.add_option("--shots", o.shots)->capture_default_str();
    app.add_option("--repeats", o.repeats)->capture_default_str();
    app.add_option("--batch", batch_size, "shots per shoot_batch call of the peer")->capture_default_str();
    app.add_option("--threads", threads, "of the peer and of the loop")->capture_default_str();
    app.add_option("--json", json_path);
    CLI11_PARSE(app, argc, argv);
    try {
        nlohmann::ordered_json doc;
        doc["machine"] = bench::machine_info();
        doc["embree"] = formfactor::EmbreeEngine::version();
        doc["settings"] = {{"shots", o.shots}, {"repeats", o.repeats}, {"batch", batch_size}, {"threads", threads}};
        nlohmann::ordered_json results = nlohmann::ordered_json::array();
        std::cout << fmt::format("{}, {} threads; {} shots × {} repeats, the peer in batches of {}\n\n",
                                 formfactor::EmbreeEngine::version(), threads, o.shots, o.repeats, batch_size);
        std::cout << "| scene | elements | N | peer ms/shot | plain loop ms/shot (robust, as the peer) | peer ÷ plain "
                     "(fastest repeats) | plain loop, not robust | robust ÷ not |\n|---|---|---|---|---|---|---|---|\n";
        for (const std::string& spec : o.scenes) {
            const bench::BenchScene s = bench::load_bench_scene(spec);
            const mesh::Mesh m = mesh::build(s.scene, bench::mesh_settings_for(o, s.scene));
            const std::vector<formfactor::ShotRequest> shots = bench::bench_shots(m, o.shots);
            std::vector<formfactor::FloatFrame> frames;
            for (const auto& shot : shots)
                frames.push_back(formfactor::float_frame(formfactor::make_frame(m.patches[shot.shooter.patch], o.seed, shot.shot)));
            const PlainScene plain(m, RTC_SCENE_FLAG_ROBUST), fast(m, RTC_SCENE_FLAG_NONE);
            const float clearance = formfactor::ray_clearance(m);  // the peer's own
            for (int n : o.hemicubes) {
                const Packets packets = make_packets(n);
                formfactor::EmbreeEngine peer(m, {n, o.seed}, threads);
                std::vector<formfactor::ShotResult> out;
                peer.shoot_batch({shots[0]}, out);  // warm-up
                plain_loop(plain.scene(), packets, {frames[0]}, clearance, threads);
                plain_loop(fast.scene(), packets, {frames[0]}, clearance, threads);
                std::vector<double> peer_ms, plain_ms, fast_ms;
                std::size_t hits = 0;
                for (int rep = 0; rep < o.repeats; ++rep) {
                    auto t0 = Clock::now();
                    hits = plain_loop(plain.scene(), packets, frames, clearance, threads);
                    plain_ms.push_back(1e3 * seconds_since(t0) / static_cast<double>(shots.size()));
                    t0 = Clock::now();
                    plain_loop(fast.scene(), packets, frames, clearance, threads);
                    fast_ms.push_back(1e3 * seconds_since(t0) / static_cast<double>(shots.size()));
                    double seconds = 0.0;
                    for (std::size_t first = 0; first < shots.size(); first += static_cast<std::size_t>(batch_size)) {
                        const std::vector<formfactor::ShotRequest> batch = bench::shots_from(shots, first, batch_size);
                        t0 = Clock::now();
                        peer.shoot_batch(batch, out);
                        seconds += seconds_since(t0);
                    }
                    peer_ms.push_back(1e3 * seconds / static_cast<double>(shots.size()));
                }
                const std::size_t rays = 3u * static_cast<std::size_t>(n) * n * shots.size();
                if (s.closed && hits != rays)
                    throw std::runtime_error(fmt::format(
                        "{} at N = {}: the plain loop hit with {} of {} rays in a closed scene", spec, n, hits, rays));
                const bench::Stats peer_stats = bench::stats(peer_ms), plain_stats = bench::stats(plain_ms),
                                   fast_stats = bench::stats(fast_ms);
                // Medians as hemirad bench reports them; on a busy machine the fastest repeats are
                // nearer what each costs alone, so their ratio is given too.
                const double fraction = plain_stats.median / peer_stats.median;
                const double fraction_min = plain_stats.min / peer_stats.min;
                const double robust_cost = plain_stats.median / fast_stats.median;
                std::cout << fmt::format(
                    "| {} | {} | {} | {:.3g} (±{:.0f}%) | {:.3g} (±{:.0f}%) | {:.0f}% ({:.0f}%) | {:.3g} (±{:.0f}%) | "
                    "{:.2f}× |\n",
                    spec, m.elements.size(), n, peer_stats.median, peer_stats.sigma_percent, plain_stats.median,
                    plain_stats.sigma_percent, 100.0 * fraction, 100.0 * fraction_min, fast_stats.median,
                    fast_stats.sigma_percent, robust_cost);
                results.push_back({{"scene", spec},
                                   {"triangles", s.scene.triangles.size()},
                                   {"elements", m.elements.size()},
                                   {"hemicube", n},
                                   {"peer_ms_per_shot",
                                    {{"min", peer_stats.min},
                                     {"median", peer_stats.median},
                                     {"sigma_percent", peer_stats.sigma_percent}}},
                                   {"plain_ms_per_shot",
                                    {{"min", plain_stats.min},
                                     {"median", plain_stats.median},
                                     {"sigma_percent", plain_stats.sigma_percent}}},
                                   {"plain_not_robust_ms_per_shot",
                                    {{"min", fast_stats.min},
                                     {"median", fast_stats.median},
                                     {"sigma_percent", fast_stats.sigma_percent}}},
                                   {"fraction_of_plain", fraction},
                                   {"fraction_of_plain_min", fraction_min},
                                   {"robust_over_not", robust_cost}});
            }
        }
        doc["results"] = results;
        if (!json_path.empty()) std::ofstream(json_path) << doc.dump(2) << "\n";
    } catch (const std::exception& e) {
        std::cerr << "hemirad_bench_embree: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
