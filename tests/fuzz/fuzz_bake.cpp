// libFuzzer target for the whole bake: the input bytes drive the random-scene generator (a glTF of
// spheres, cylinders, tori, boxes, thin walls and degenerate triangles under nested rotated,
// scaled and mirrored nodes) and the bake's settings; the scene is baked by bake::run, as the CLI
// runs it, at small settings (N 16–32, coarse patches, at most 300 passes), on the reference
// engine and, for inputs that ask and where an OpenCL device is present, again on OpenCL. A bake
// must succeed or refuse its input with an InputError; anything else (a crash, a sanitizer
// report, another exception) is a finding, and so is a broken invariant: a shot's F < 0 or
// ΣF + blocked > 1 + 1e-9, non-finite or unbalanced books, a negative radiosity, a baked glTF that
// does not load, an OpenCL bake that differs from the reference's. Built and run by run_fuzz.sh.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iostream>
#include <streambuf>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "bake/bake.h"
#include "core/error.h"
#include "random_bake.h"
#include "gen/random_scene.h"

namespace {

using namespace hemirad;

bool g_opencl = false;
// The input being run: a finding prints it, so that it can be run again from the log alone.
const std::uint8_t* g_data = nullptr;
std::size_t g_size = 0;

// What the run did, printed at exit.
struct Tally {
    long inputs = 0, baked = 0, refused = 0, on_opencl = 0, matrix = 0, progressive = 0, shots = 0;
} g_tally;

void print_tally() {
    std::fprintf(stderr,
                 "fuzz_bake: %ld inputs: %ld baked (%ld by the matrix solver, %ld progressively; %ld also on "
                 "OpenCL, identical), %ld refused with an InputError by design; %ld shots checked\n",
                 g_tally.inputs, g_tally.baked, g_tally.matrix, g_tally.progressive, g_tally.on_opencl, g_tally.refused,
                 g_tally.shots);
}

// Swallows std::cerr: a bake warns there even when quiet (the scene's warnings), thousands of
// times in a run. Findings go to stderr through stdio, and sanitizer reports straight to fd 2.
class NullBuffer : public std::streambuf {
protected:
    int overflow(int c) override { return c; }
};

[[noreturn]] void finding(const test::RandomBake& bake, const std::string& what,
                          const std::vector<std::string>& details = {}) {
    std::fprintf(stderr, "fuzz_bake: FINDING: %s\n  scene: %s\n  settings: %s (device %s)\n", what.c_str(),
                 bake.scene.summary.c_str(), bake.settings.c_str(), bake.options.device.c_str());
    for (const std::string& d : details) std::fprintf(stderr, "  %s\n", d.c_str());
    // The input's bytes, in hex on one line (at most 2 × 4096 digits): `xxd -r -p` turns them back.
    std::fprintf(stderr, "fuzz_bake: input (%zu bytes, hex): ", g_size);
    for (std::size_t i = 0; i < g_size; ++i) std::fprintf(stderr, "%02x", g_data[i]);
    std::fprintf(stderr, "\n");
    std::abort();
}

// Runs one bake: true when it baked, false (with the message in `refusal`) when it refused its
// input with an InputError, the clean way to refuse bad input.
bool bake_or_refuse(const test::RandomBake& bake, const bake::Options& options, std::string& refusal) {
    try {
        bake::run(options);
        return true;
    } catch (const InputError& e) {
        refusal = e.what();
        return false;
    } catch (const std::exception& e) {
        test::RandomBake shown = bake;
        shown.options.device = options.device;
        finding(shown, std::string("not an InputError: ") + e.what());
    }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    static NullBuffer null;
    std::cerr.rdbuf(&null);
    g_opencl = !ocl::list_devices().empty();
    std::atexit(print_tally);
    std::fprintf(stderr, "fuzz_bake: %s\n",
                 g_opencl ? "an OpenCL device is present: inputs that ask are baked on OpenCL too"
                          : "no OpenCL device: the reference engine only");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    g_data = data;
    g_size = size;
    test::ScratchDir dir("hemirad-fuzz-bake");
    gen::Choices choices(data, size);
    // Smaller than the seeded test's: a run is worth many inputs more than a few large ones.
    test::RandomBakeLimits limits;
    limits.scene.max_objects = 4;
    limits.scene.max_triangles = 160;
    limits.finest_patches = 7;
    limits.most_elements = 2;
    limits.most_passes = 80;
    test::RandomBake bake = test::make_random_bake(choices, dir.path(), limits);
    const bool on_opencl = g_opencl && choices.chance(0.25);

    test::ShotChecker shots;
    bake::Options options = bake.options;
    options.on_shot = std::ref(shots);
    std::string refusal;
    ++g_tally.inputs;
    if (!bake_or_refuse(bake, options, refusal)) {
        // Generated scenes are valid glTF with an emitter: only the settings may be refused.
        if (!test::refused_by_design(options)) finding(bake, "a generated scene was refused: " + refusal);
        ++g_tally.refused;
        return 0;
    }
    ++g_tally.baked;
    g_tally.shots += shots.shots();
    const std::string solver =
        nlohmann::json::parse(test::read_file_text(std::filesystem::path(options.output) / "report.json")).at("settings").at("solver");
    ++(solver == "matrix" ? g_tally.matrix : g_tally.progressive);
    if (!shots.problems().empty()) finding(bake, "a shot breaks the form-factor invariants", shots.problems());
    if (const auto problems = test::check_bake_output(options.output); !problems.empty())
        finding(bake, "the outputs break an invariant", problems);

    if (on_opencl) {
        test::ShotChecker cl_shots;
        bake::Options cl = bake.options;
        cl.device = "opencl";
        cl.output = (dir.path() / "out_opencl").string();
        cl.on_shot = std::ref(cl_shots);
        bake.options.device = "opencl";
        if (!bake_or_refuse(bake, cl, refusal)) finding(bake, "OpenCL refused what the reference baked: " + refusal);
        if (!cl_shots.problems().empty()) finding(bake, "an OpenCL shot breaks the invariants", cl_shots.problems());
        if (const auto d = test::compare_bakes(options.output, cl.output); !d.empty())
            finding(bake, "the OpenCL bake differs from the reference bake", d);
        ++g_tally.on_opencl;
    }
    return 0;
}
