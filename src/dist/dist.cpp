// MPI ranks as members of a sharded engine (see dist.h).
#include "dist/dist.h"

#include <fmt/format.h>

#include <cstdlib>
#include <cstring>
#include <iostream>
#include <map>
#include <type_traits>

#include "cl/runtime.h"
#include "core/error.h"

#ifdef HEMIRAD_HAVE_MPI
#include <mpi.h>

#include <chrono>
#include <mutex>
#include <thread>
#endif

namespace hemirad::dist {
namespace {

// Bytes in, bytes out: trivially copyable values and vectors of them, in the machine's layout
// (every rank runs the same build on the same kind of machine).
class Writer {
public:
    template <class T>
    void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        out_.append(reinterpret_cast<const char*>(&v), sizeof(T));
    }
    template <class T>
    void put_vector(const std::vector<T>& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        put<std::uint64_t>(v.size());
        if (!v.empty()) out_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
    }
    void put_string(const std::string& s) {
        put<std::uint64_t>(s.size());
        out_ += s;
    }
    std::string take() { return std::move(out_); }

private:
    std::string out_;
};

class Reader {
public:
    explicit Reader(const std::string& in) : in_(in) {}
    template <class T>
    T get() {
        static_assert(std::is_trivially_copyable_v<T>);
        T v;
        std::memcpy(&v, take(sizeof(T)), sizeof(T));
        return v;
    }
    template <class T>
    std::vector<T> get_vector() {
        const auto n = get<std::uint64_t>();
        if (n > (in_.size() - at_) / sizeof(T)) throw InternalError("dist: a message ends early");
        std::vector<T> v(n);
        if (n > 0) std::memcpy(v.data(), take(n * sizeof(T)), n * sizeof(T));
        return v;
    }
    std::string get_string() {
        const auto n = get<std::uint64_t>();
        return std::string(take(n), n);
    }
    bool done() const { return at_ == in_.size(); }

private:
    const char* take(std::size_t n) {
        if (n > in_.size() - at_) throw InternalError("dist: a message ends early");
        const char* p = in_.data() + at_;
        at_ += n;
        return p;
    }
    const std::string& in_;
    std::size_t at_ = 0;
};

}  // namespace

std::string pack_mesh(const mesh::Mesh& m) {
    Writer w;
    w.put_vector(m.patches);
    w.put_vector(m.lights);
    w.put_vector(m.directions);
    w.put_vector(m.gather_points);
    w.put_vector(m.elements);
    for (const std::size_t n : {m.dropped_triangles, m.quads, m.clusters, m.split_clusters, m.moved_clusters, m.joined_clusters,
                                m.texture_splits, m.holes, m.emission_splits, m.emission_unsplit})
        w.put<std::uint64_t>(n);
    return w.take();
}

mesh::Mesh unpack_mesh(const std::string& bytes) {
    Reader r(bytes);
    mesh::Mesh m;
    m.patches = r.get_vector<mesh::Patch>();
    m.lights = r.get_vector<mesh::LightShooter>();
    m.directions = r.get_vector<mesh::DirectionalShooter>();
    m.gather_points = r.get_vector<mesh::GatherPoint>();
    m.elements = r.get_vector<mesh::Element>();
    for (std::size_t* n : {&m.dropped_triangles, &m.quads, &m.clusters, &m.split_clusters, &m.moved_clusters, &m.joined_clusters,
                           &m.texture_splits, &m.holes, &m.emission_splits, &m.emission_unsplit})
        *n = static_cast<std::size_t>(r.get<std::uint64_t>());
    if (!r.done()) throw InternalError("dist: a mesh message is longer than its mesh");
    return m;
}

std::string pack_shots(std::uint64_t mesh_id, const std::vector<formfactor::ShotRequest>& shots) {
    Writer w;
    w.put(mesh_id);
    w.put<std::uint64_t>(shots.size());
    for (const formfactor::ShotRequest& s : shots) {
        w.put(static_cast<std::uint8_t>(s.shooter.kind));
        w.put(s.shooter.patch);
        w.put(s.shot);
    }
    return w.take();
}

std::vector<formfactor::ShotRequest> unpack_shots(const std::string& bytes, std::uint64_t& mesh_id) {
    Reader r(bytes);
    mesh_id = r.get<std::uint64_t>();
    std::vector<formfactor::ShotRequest> shots(r.get<std::uint64_t>());
    for (formfactor::ShotRequest& s : shots) {
        const auto kind = r.get<std::uint8_t>();
        if (kind > static_cast<std::uint8_t>(formfactor::Shooter::Kind::directional))
            throw InternalError("dist: a shot of no kind");
        s.shooter.kind = static_cast<formfactor::Shooter::Kind>(kind);
        s.shooter.patch = r.get<std::uint32_t>();
        s.shot = r.get<std::uint64_t>();
    }
    if (!r.done()) throw InternalError("dist: a shots message is longer than its shots");
    return shots;
}

std::string pack_rows(const std::vector<formfactor::ShotResult>& rows) {
    Writer w;
    w.put<std::uint64_t>(rows.size());
    for (const formfactor::ShotResult& row : rows) {
        w.put(row.blocked);
        w.put_vector(row.element);
        w.put_vector(row.F);
    }
    return w.take();
}

std::vector<formfactor::ShotResult> unpack_rows(const std::string& bytes) {
    Reader r(bytes);
    std::vector<formfactor::ShotResult> rows(r.get<std::uint64_t>());
    for (formfactor::ShotResult& row : rows) {
        row.blocked = r.get<double>();
        row.element = r.get_vector<std::uint32_t>();
        row.F = r.get_vector<double>();
        if (row.element.size() != row.F.size()) throw InternalError("dist: a row with more elements than values");
    }
    if (!r.done()) throw InternalError("dist: a rows message is longer than its rows");
    return rows;
}

int launched_processes() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"})
        if (const char* v = std::getenv(name); v && *v) {
            char* end = nullptr;
            const long n = std::strtol(v, &end, 10);
            if (end && *end == '\0' && n > 0) return static_cast<int>(std::min<long>(n, 1 << 20));
        }
    return 1;
}

#ifndef HEMIRAD_HAVE_MPI

bool built_with_mpi() { return false; }
Session::Session(int&, char**&) {}
Session::~Session() = default;
int rank() { return 0; }
int size() { return 1; }
int serve(const EngineFactory&, const std::function<std::string(const std::exception&)>&) { return 1; }
std::vector<RemoteMember> remote_engines(const mesh::Mesh&, const formfactor::Settings&, int) { return {}; }
Traffic traffic() { return {}; }

#else

namespace {

enum Tag : int { kMesh = 1, kShots = 2, kRows = 3, kFail = 4, kDrop = 5, kQuit = 6 };
constexpr std::size_t kPart = std::size_t{1} << 30;  // bytes per MPI message: counts are ints
// Polling backs off from kPollFirst to kPollLast while nothing arrives: a shot takes milliseconds,
// and every wake-up is time taken from the compute threads of a rank's core (polling every 50 µs
// cost two ranks on two cores a sixth of their throughput).
constexpr auto kPollFirst = std::chrono::microseconds(20), kPollLast = std::chrono::microseconds(1000);
constexpr auto kPollClose = std::chrono::microseconds(100);  // rank 0 waiting for rows it expects soon

bool g_started = false;
int g_rank = 0, g_size = 1;
std::mutex g_mpi;  // every MPI call, so that the sharded engine's threads may each wait on a rank
Traffic g_traffic;
std::uint64_t g_next_mesh = 1;

// mpirun (Open MPI, MPICH's hydra) and srun set these in every rank's environment.
bool launched_by_mpi() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
        if (const char* v = std::getenv(name); v && *v) return true;
    return false;
}

void check(int rc, int peer, const char* what) {
    if (rc == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(rc, text, &length);
    throw ocl::DeviceError(fmt::format("rank {}: {} failed: {}", peer, what, std::string(text, static_cast<std::size_t>(length))));
}

// A message: its length, then its bytes in parts of at most kPart. Under g_mpi.
void send_locked(int peer, int tag, const std::string& bytes) {
    std::uint64_t n = bytes.size();
    check(MPI_Send(&n, 1, MPI_UINT64_T, peer, tag, MPI_COMM_WORLD), peer, "MPI_Send");
    for (std::size_t at = 0; at < bytes.size(); at += kPart)
        check(MPI_Send(bytes.data() + at, static_cast<int>(std::min(kPart, bytes.size() - at)), MPI_BYTE, peer, tag,
                       MPI_COMM_WORLD),
              peer, "MPI_Send");
}

void send(int peer, int tag, const std::string& bytes) {
    std::lock_guard lock(g_mpi);
    send_locked(peer, tag, bytes);
}

// The next message from `peer`, polled so that a waiting rank leaves its core to the work (MPI's
// blocking receive spins). Returns its tag.
int receive(int peer, std::string& bytes, std::chrono::microseconds last = kPollLast) {
    for (auto wait = kPollFirst;; wait = std::min(wait * 2, last)) {
        {
            std::lock_guard lock(g_mpi);
            int flag = 0;
            MPI_Status status;
            check(MPI_Iprobe(peer, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &status), peer, "MPI_Iprobe");
            if (flag) {
                const int tag = status.MPI_TAG;
                std::uint64_t n = 0;
                check(MPI_Recv(&n, 1, MPI_UINT64_T, peer, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE), peer, "MPI_Recv");
                bytes.resize(n);
                for (std::size_t at = 0; at < n; at += kPart)
                    check(MPI_Recv(bytes.data() + at, static_cast<int>(std::min<std::size_t>(kPart, n - at)), MPI_BYTE, peer,
                                   tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
                          peer, "MPI_Recv");
                return tag;
            }
        }
        std::this_thread::sleep_for(wait);
    }
}

std::string first_line(const std::string& text) { return text.substr(0, text.find('\n')); }

// A worker's engine, seen from rank 0.
class RemoteEngine final : public formfactor::Engine {
public:
    RemoteEngine(int peer, std::uint64_t mesh_id) : peer_(peer), mesh_id_(mesh_id) {}
    ~RemoteEngine() override {
        try {
            Writer w;
            w.put(mesh_id_);
            send(peer_, kDrop, w.take());
        } catch (...) {  // the world is going down: nothing to free
        }
    }
    std::string name() const override { return fmt::format("rank {}", peer_); }
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        shoot_batch({request}, one_);
        out = std::move(one_.front());
    }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots, std::vector<formfactor::ShotResult>& out) override {
        const std::string request = pack_shots(mesh_id_, shots);
        {
            std::lock_guard lock(g_mpi);
            send_locked(peer_, kShots, request);
            g_traffic.shot_bytes += request.size();
            ++g_traffic.shot_messages;
        }
        // Asleep for most of the time the rank took for as many shots last time, then polled
        // closely: a rank's answer is noticed within a fraction of a shot.
        const auto t0 = std::chrono::steady_clock::now();
        if (seconds_per_shot_ > 0.0)
            std::this_thread::sleep_for(std::chrono::duration<double>(0.8 * seconds_per_shot_ * static_cast<double>(shots.size())));
        std::string reply;
        const int tag = receive(peer_, reply, kPollClose);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        seconds_per_shot_ = seconds / static_cast<double>(std::max<std::size_t>(1, shots.size()));
        if (tag == kFail) {
            Reader r(reply);
            const bool device = r.get<std::uint8_t>() != 0;
            const std::string why = r.get_string();
            if (device) throw ocl::DeviceError(why);
            throw std::runtime_error(why);
        }
        if (tag != kRows) throw InternalError(fmt::format("rank {}: answered shots with message {}", peer_, tag));
        {
            std::lock_guard lock(g_mpi);
            g_traffic.row_bytes += reply.size();
            ++g_traffic.row_messages;
        }
        out = unpack_rows(reply);
        if (out.size() != shots.size())
            throw InternalError(fmt::format("rank {}: {} rows for {} shots", peer_, out.size(), shots.size()));
    }

private:
    int peer_;
    std::uint64_t mesh_id_;
    std::vector<formfactor::ShotResult> one_;
    double seconds_per_shot_ = 0.0;  // the last answer's time over its shots
};

}  // namespace

bool built_with_mpi() { return true; }

Session::Session(int& argc, char**& argv) {
    if (g_started || !launched_by_mpi()) return;
    int provided = 0;
    if (MPI_Init_thread(&argc, &argv, MPI_THREAD_MULTIPLE, &provided) != MPI_SUCCESS) {
        std::cerr << "hemirad: MPI_Init_thread failed\n";
        std::exit(1);
    }
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
    MPI_Comm_size(MPI_COMM_WORLD, &g_size);
    g_started = true;
    if (provided < MPI_THREAD_SERIALIZED) {
        if (g_rank == 0) std::cerr << "hemirad: this MPI gives no thread support (MPI_THREAD_SERIALIZED at least is needed)\n";
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
}

Session::~Session() {
    if (!g_started) return;
    if (g_rank == 0)
        for (int r = 1; r < g_size; ++r) {
            try {
                send(r, kQuit, {});
            } catch (const std::exception& e) {
                std::cerr << "hemirad: " << e.what() << "\n";
            }
        }
    MPI_Finalize();
    g_started = false;
}

int rank() { return g_rank; }
int size() { return g_size; }

Traffic traffic() {
    std::lock_guard lock(g_mpi);
    return g_traffic;
}

std::vector<RemoteMember> remote_engines(const mesh::Mesh& mesh, const formfactor::Settings& settings, int ranks) {
    std::vector<RemoteMember> out;
    if (!g_started || g_rank != 0) return out;
    const int workers = ranks > 0 ? std::min(ranks, g_size - 1) : g_size - 1;
    if (workers <= 0) return out;
    const std::uint64_t id = g_next_mesh++;
    Writer w;
    w.put(id);
    w.put(settings.hemicube);
    w.put(settings.seed);
    w.put_string(pack_mesh(mesh));
    const std::string bytes = w.take();
    for (int r = 1; r <= workers; ++r) {
        {
            std::lock_guard lock(g_mpi);
            send_locked(r, kMesh, bytes);
            g_traffic.mesh_bytes += bytes.size();
            ++g_traffic.mesh_messages;
        }
        out.push_back({std::make_unique<RemoteEngine>(r, id), fmt::format("rank {}", r)});
    }
    return out;
}

int serve(const EngineFactory& factory, const std::function<std::string(const std::exception&)>& failure) {
    // Per mesh, the mesh (its engine keeps a reference) and its engine.
    struct Served {
        std::unique_ptr<mesh::Mesh> mesh;
        std::unique_ptr<formfactor::Engine> engine;
    };
    std::map<std::uint64_t, Served> engines;
    std::map<std::uint64_t, std::pair<bool, std::string>> failed;  // meshes whose engine could not be made
    const auto fail = [&](bool device, const std::string& why) {
        Writer w;
        w.put<std::uint8_t>(device ? 1 : 0);
        w.put_string(fmt::format("rank {}: {}", g_rank, first_line(why)));
        send(0, kFail, w.take());
    };
    try {
        std::string bytes;
        std::vector<formfactor::ShotResult> rows;
        for (;;) {
            const int tag = receive(0, bytes);
            if (tag == kQuit) return 0;
            if (tag == kMesh) {
                Reader r(bytes);
                const auto id = r.get<std::uint64_t>();
                formfactor::Settings settings;
                settings.hemicube = r.get<int>();
                settings.seed = r.get<std::uint64_t>();
                auto mesh = std::make_unique<mesh::Mesh>(unpack_mesh(r.get_string()));
                try {
                    auto engine = factory(*mesh, settings);
                    engines[id] = {std::move(mesh), std::move(engine)};
                } catch (const std::exception& e) {
                    const std::string why = failure ? failure(e) : std::string();
                    failed[id] = {!why.empty(), why.empty() ? e.what() : why};
                }
            } else if (tag == kDrop) {
                Reader r(bytes);
                const auto id = r.get<std::uint64_t>();
                engines.erase(id);
                failed.erase(id);
            } else if (tag == kShots) {
                std::uint64_t id = 0;
                const std::vector<formfactor::ShotRequest> shots = unpack_shots(bytes, id);
                if (const auto f = failed.find(id); f != failed.end()) {
                    fail(f->second.first, f->second.second);
                    continue;
                }
                const auto e = engines.find(id);
                if (e == engines.end()) {
                    fail(false, fmt::format("shots for mesh {}, which it was never sent", id));
                    continue;
                }
                try {
                    e->second.engine->shoot_batch(shots, rows);
                } catch (const std::exception& x) {
                    const std::string why = failure ? failure(x) : std::string();
                    fail(!why.empty(), why.empty() ? x.what() : why);
                    continue;
                }
                send(0, kRows, pack_rows(rows));
            } else {
                throw InternalError(fmt::format("message {} from rank 0", tag));
            }
        }
    } catch (const std::exception& e) {
        std::cerr << "hemirad: rank " << g_rank << ": " << e.what() << "\n";
        return 1;
    }
}

#endif

}  // namespace hemirad::dist
