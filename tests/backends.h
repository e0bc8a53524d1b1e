// The form-factor engines as test parameters, as mitsuba3 runs its tests once per variant: ONE list
// of every kind of engine this build and machine could have, each present or absent with the
// reason, and a factory for it. A test over every backend draws the names with Catch2's GENERATE
// and skips the absent ones visibly (HEMIRAD_SKIP_ABSENT, the one skip macro of the tests):
//
//     const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
//     HEMIRAD_SKIP_ABSENT(b);
//     INFO("backend " << b.name);
//     const std::unique_ptr<formfactor::Engine> engine = b.make(mesh, settings);
//
// The list, in order:
// - `ref`: formfactor::ReferenceEngine, always (--device ref);
// - `opencl:P.D`: formfactor::OpenCLEngine on each OpenCL device (--device opencl:P.D); one
//   absent entry `opencl` where there is none;
// - `embree`: formfactor::EmbreeEngine where built with Embree (no --device: a bench engine);
// - `sharded`: formfactor::ShardedEngine over the reference and the first OpenCL device
//   (--device ref,opencl:P.D), or over two references where there is no device (no --device:
//   a list may not name ref twice);
// - `ranks`: MPI worker ranks, which exist only in processes mpirun started (tests/mpi's
//   scripts run those bakes): absent in process, with the reason.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/engine.h"
#include "mesh/mesh.h"

namespace hemirad::test {

struct Backend {
    std::string name;        // "ref", "opencl:0.0", "embree", "sharded", "ranks"
    bool present = false;
    std::string why;         // why absent (empty when present)
    // The --device value a bake on this backend takes; empty where there is none.
    std::string device;
    // Whether its rows are the reference's bit for bit (every hemicube rasterizer and any sharing
    // of them); the ray caster agrees but for float rounding on cell centres near edges and ties.
    bool exact = true;
    // A new engine on `mesh` (which it must not outlive); only for a present backend.
    std::function<std::unique_ptr<formfactor::Engine>(const mesh::Mesh&, const formfactor::Settings&)> make;
    // The OpenCL device's context (kept for the process), for opencl:P.D; nullptr otherwise.
    ocl::Context* context() const;

    std::shared_ptr<ocl::Context> context_;
};

// Presence of something a test needs, where it is not an engine of the list (a bake's --device).
struct Presence {
    std::string name;
    bool present = false;
    std::string why;
};

// Every backend, present or not, in the order above (made once per process).
const std::vector<Backend>& backends();
// Their names, for GENERATE(from_range(...)).
std::vector<std::string> backend_names();
// The backend named `name` (as backend_names() spells it); throws std::out_of_range otherwise.
const Backend& backend(const std::string& name);
// The first OpenCL device's entry, or the absent `opencl` one: for tests of the OpenCL engine's own
// workings (kernels, tuning, faults).
const Backend& first_opencl();
// Whether a bake can run on `b` (present, with a --device), and why not.
Presence bakeable(const Backend& b);

}  // namespace hemirad::test

// Ends the test (the current GENERATE value of it) visibly where `what` (a Backend or a Presence) is
// absent: a warning "<name> absent: <why>; skipped". Catch2 v2 has no SKIP. The one skip macro of
// the tests.
#define HEMIRAD_SKIP_ABSENT(what)                                                           \
    do {                                                                                   \
        const auto& hemirad_absent_ = (what);                                              \
        if (!hemirad_absent_.present) {                                                    \
            WARN(hemirad_absent_.name << " absent: " << hemirad_absent_.why << "; skipped"); \
            return;                                                                        \
        }                                                                                  \
    } while (false)
