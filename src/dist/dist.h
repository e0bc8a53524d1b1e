// Bakes across machines with MPI: one rank per machine or per device. Rank 0 reads the scene,
// owns the solver and writes every output and checkpoint; every other rank is a worker that
// receives each mesh once and computes the rows of the shots it is sent (serve()). On rank 0 a
// worker is one more member of a formfactor::ShardedEngine (remote_engines()), so batches are
// shared among ranks exactly as among the devices of one machine, with the same rows.
//
// Built with MPI where CMake finds it (HEMIRAD_HAVE_MPI); without it, or in a process that
// mpirun or srun did not start, the world is rank 0 of 1 and nothing here talks to anyone.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "formfactor/engine.h"
#include "mesh/mesh.h"

namespace hemirad::dist {

// Whether this build has MPI.
bool built_with_mpi();

// The MPI world of this process, started by the first Session of the process (when mpirun or srun
// launched it: their environment says so) and ended by its destructor, which on rank 0 first
// tells every worker to stop. Without MPI, or launched alone: rank 0 of 1.
class Session {
public:
    Session(int& argc, char**& argv);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};
int rank();
int size();  // ranks in the world (1 without MPI)

// How many processes mpirun or srun started, as their environment says (1 when none did): a
// build without MPI that finds more than one refuses to run, as each would bake the whole scene
// into the same output.
int launched_processes();

// Makes a worker's engine for a mesh it was sent (its own --device); throws on failure (the
// worker sends the reason back with the next shots for that mesh).
using EngineFactory =
    std::function<std::unique_ptr<formfactor::Engine>(const mesh::Mesh& mesh, const formfactor::Settings& settings)>;

// A worker's loop (rank > 0): meshes, shots and rows until rank 0 says stop. `failure` is the
// one-line reason when an exception is its device's failure (empty for any other): rank 0 then
// treats the rank as a failed device. Returns the exit code: 0 when told to stop, 1 when the
// link to rank 0 failed.
int serve(const EngineFactory& factory, const std::function<std::string(const std::exception&)>& failure);

// On rank 0: an engine per worker rank (1 .. size−1, or `ranks` of them when > 0) for `mesh`,
// which each is sent once now. Each computes its rows on its rank; an MPI failure or the
// worker's device failing throws ocl::DeviceError naming the rank. Empty without workers.
struct RemoteMember {
    std::unique_ptr<formfactor::Engine> engine;
    std::string id;  // "rank 2"
};
std::vector<RemoteMember> remote_engines(const mesh::Mesh& mesh, const formfactor::Settings& settings, int ranks = 0);

// Bytes sent to and received from workers so far by this process (rank 0), by kind: what the
// scaling model (bench/scaling_model.py) is fed.
struct Traffic {
    std::uint64_t mesh_bytes = 0, shot_bytes = 0, row_bytes = 0;
    std::uint64_t mesh_messages = 0, shot_messages = 0, row_messages = 0;
};
Traffic traffic();

// The mesh as bytes and back (what a worker is sent): every field, exactly.
std::string pack_mesh(const mesh::Mesh& mesh);
mesh::Mesh unpack_mesh(const std::string& bytes);

// A batch of shots and their rows as bytes and back, exactly.
std::string pack_shots(std::uint64_t mesh_id, const std::vector<formfactor::ShotRequest>& shots);
std::vector<formfactor::ShotRequest> unpack_shots(const std::string& bytes, std::uint64_t& mesh_id);
std::string pack_rows(const std::vector<formfactor::ShotResult>& rows);
std::vector<formfactor::ShotResult> unpack_rows(const std::string& bytes);

}  // namespace hemirad::dist
