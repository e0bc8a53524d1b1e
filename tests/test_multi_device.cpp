// Bakes whose batches several devices share (--device all, a list): PoCL shows two devices when
// POCL_DEVICES names two, so two CPU devices stand in for a machine's GPUs. The output is byte for
// byte that of one device with the same batch; a failing automatic device drops out.
#include <catch2/catch.hpp>

#include "backends.h"
#include "cl/runtime.h"
#include "cli_support.h"

using namespace hemirad;
using namespace hemirad::test;

namespace {

// Two PoCL devices (their ids opencl:0.0 and opencl:0.1 where PoCL is the only platform).
const std::string kTwoDevices = "POCL_DEVICES='pthread pthread' ";

bool pocl_only() {
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    return !devices.empty() && devices.front().platform_name.find("Portable Computing Language") != std::string::npos &&
           devices.back().platform == 0;
}

test::Presence two_pocl_devices() {
    return {"two PoCL devices (POCL_DEVICES)", pocl_only(), "PoCL is not the only OpenCL platform here"};
}

}  // namespace

TEST_CASE("multi-device: two devices, and the reference with one, bake byte for byte as one device", "[cli][multi]") {
    HEMIRAD_SKIP_ABSENT(two_pocl_devices());
    const TempDir dir;
    const std::vector<std::string> args = concat(kFast, {"--solver", "progressive"});
    const fs::path one = dir / "one", all = dir / "all", mixed = dir / "mixed", fixed = dir / "fixed",
                   fixed_all = dir / "fixed_all";
    // Without --batch: a step shoots the patches that hold about as much as the most, whatever
    // the devices, so one device and two bake the same bytes.
    const json o = bake_ok(dir, kClosedRoom, one, concat(args, {"--device", "opencl:0.0"}));
    CHECK(o["settings"]["batch"] == 256);
    CHECK(o["settings"]["batch_share"] == 0.5);
    CHECK_FALSE(o["device"].contains("members"));
    // Its steps took several shooters: fewer engine calls than passes.
    CHECK(o["steps"]["largest"].get<long>() > 1);
    CHECK(o["steps"]["count"].get<long>() < o["passes"].get<long>());

    RunResult r = run_hemirad(dir, bake_args(kClosedRoom, all, concat(args, {"--device", "all"})), kTwoDevices);
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    const json report = read_json(all / "report.json");
    CHECK(report["settings"]["batch"] == 256);
    CHECK(report["device"]["id"] == "opencl:0.0,opencl:0.1");
    REQUIRE(report["device"]["members"].size() == 2);
    long shots = 0;
    for (const json& m : report["device"]["members"]) {
        CHECK(m["shots"].get<long>() > 0);
        CHECK_FALSE(m.contains("dropped"));
        shots += m["shots"].get<long>();
    }
    CHECK(shots > report["passes"].get<long>());  // the solve's shots and the gather's
    CHECK(read_text(all / "baked.bin") == read_text(one / "baked.bin"));

    // The scalar reference beside a device: the reference's bits, so the same bytes.
    const json m = bake_ok(dir, kClosedRoom, mixed, concat(args, {"--device", "ref,opencl:0.0"}));
    CHECK(m["device"]["backend"] == "ref+opencl");
    CHECK(read_text(mixed / "baked.bin") == read_text(one / "baked.bin"));

    // A batch given is the top K each step, the same on one device and two; another order of
    // shooting than the default's, so other bytes.
    const json f = bake_ok(dir, kClosedRoom, fixed, concat(args, {"--device", "opencl:0.0", "--batch", "32"}));
    CHECK(f["settings"]["batch"] == 32);
    CHECK(f["settings"]["batch_share"] == 0.0);
    CHECK(f["steps"]["largest"] == 32);
    r = run_hemirad(dir, bake_args(kClosedRoom, fixed_all, concat(args, {"--device", "all", "--batch", "32"})), kTwoDevices);
    REQUIRE(r.code == 0);
    CHECK(read_text(fixed_all / "baked.bin") == read_text(fixed / "baked.bin"));
    CHECK(read_text(fixed / "baked.bin") != read_text(one / "baked.bin"));
}

TEST_CASE("multi-device: a sunlit bake sends its suns' parallel shots to the devices like any shots, byte for byte as one "
          "device", "[cli][multi][sun]") {
    HEMIRAD_SKIP_ABSENT(two_pocl_devices());
    // The atrium's sun and a second from --sun: two directional shots, one batch of the lights.
    // Without refinement and the final gather, every shot of the bake is the solve's: the row
    // cache's requests are the passes and the suns' shots, and what it did not have in hand went
    // to the members. (Before suns were shooters, they took a second door past the devices, and
    // the requests were the passes alone.)
    const TempDir dir;
    const fs::path atrium = kSourceDir / "scenes" / "atrium.gltf";
    const long suns = 2, batch = 2;
    const std::vector<std::string> args =
        concat(kFast, {"--solver", "progressive", "--batch", std::to_string(batch), "--gather", "0", "--refine-levels", "0",
                       "--sun", "135,40,10"});
    const fs::path one = dir / "one", all = dir / "all";
    const json single = bake_ok(dir, atrium, one, concat(args, {"--device", "opencl:0.0"}));
    const RunResult r = run_hemirad(dir, bake_args(atrium, all, concat(args, {"--device", "all"})), kTwoDevices);
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    const json report = read_json(all / "report.json");
    CHECK(read_text(all / "baked.bin") == read_text(one / "baked.bin"));
    REQUIRE(report["device"]["members"].size() == 2);
    long shots = 0;
    for (const json& m : report["device"]["members"]) {
        CHECK(m["shots"].get<long>() > 0);
        shots += m["shots"].get<long>();
    }
    const json& cache = report["row_cache"];
    INFO("passes " << report["passes"] << ", row cache " << cache.dump());
    CHECK(shots == cache["shot"].get<long>());
    // The last batch may be cut short by convergence: up to batch − 1 requests beyond the passes.
    const long extra = cache["requests"].get<long>() - report["passes"].get<long>() - suns;
    CHECK(extra >= 0);
    CHECK(extra < batch);
    CHECK(single["row_cache"]["requests"] == cache["requests"]);
    CHECK(single["energy"]["emitted"] == report["energy"]["emitted"]);
}

TEST_CASE("multi-device: a failing device of `all` drops out and its shots are redone, and a named one stops the bake",
          "[cli][multi][faults]") {
    HEMIRAD_SKIP_ABSENT(two_pocl_devices());
    const TempDir dir;
    const std::vector<std::string> args = concat(kFast, {"--solver", "progressive", "--batch", "16"});
    const fs::path one = dir / "one", dropped = dir / "dropped", named = dir / "named";
    bake_ok(dir, kClosedRoom, one, concat(args, {"--device", "opencl:0.0"}));
    const std::string fault = kTwoDevices + "HEMIRAD_FAULT=fail-after:2,device:opencl:0.1 ";
    RunResult r = run_hemirad(dir, bake_args(kClosedRoom, dropped, concat(args, {"--device", "all"})), fault);
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    const json report = read_json(dropped / "report.json");
    CHECK(report["warnings"].dump().find("opencl:0.1 failed and left the bake") != std::string::npos);
    REQUIRE(report["device"]["members"].size() == 2);
    CHECK(report["device"]["members"][1]["dropped"].get<std::string>().find("CL_INVALID_COMMAND_QUEUE") != std::string::npos);
    CHECK_FALSE(report["device"]["members"][0].contains("dropped"));
    CHECK_FALSE(report["device"].contains("fallback"));
    CHECK(read_text(dropped / "baked.bin") == read_text(one / "baked.bin"));

    r = run_hemirad(dir, bake_args(kClosedRoom, named, concat(args, {"--device", "opencl:0.0,opencl:0.1"})), fault);
    CHECK(r.code == 1);
    CHECK(r.err.find("hemirad: device failed: ") != std::string::npos);
    CHECK_FALSE(fs::exists(named));
}

TEST_CASE("multi-device: malformed device lists and faults are one line and exit 2", "[cli][multi]") {
    const TempDir dir;
    const auto refused = [&](const std::vector<std::string>& extra, const std::string& env, const std::string& says) {
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, dir / "never", concat(kFast, extra)), env);
        INFO("stderr: " << r.err);
        CHECK(r.code == 2);
        CHECK(r.err.find(says) != std::string::npos);
        CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
        CHECK_FALSE(fs::exists(dir / "never"));
    };
    refused({"--device", "ref,ref"}, "", "names ref twice");
    refused({"--device", "auto,ref"}, "", "a list holds ref, opencl and opencl:P.D, not 'auto'");
    refused({"--device", "ref,opencl:7.7"}, "", "no such OpenCL device");
    refused({"--device", "ref,"}, "", "not ''");
    refused({"--device", "ref"}, "HEMIRAD_FAULT=device:gpu0 ", "expected device:opencl:P.D");
    if (!ocl::list_devices().empty()) refused({"--device", "all", "--verify"}, kTwoDevices, "--verify checks one OpenCL device");
}
