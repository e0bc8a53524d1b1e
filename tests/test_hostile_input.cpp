// The hostile-input probe's defects (issue 42), each as it was found: outputs that replaced the
// scene's own files, small files that asked for unbounded memory, a documented kernel knob that
// crashed PoCL, signals that left staging behind or were not heard, a lamp masked away in
// silence, and options whose empty or hex values were taken. Every test runs the real binary.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <map>
#include <set>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "backends.h"
#include "cl/runtime.h"
#include "cli_support.h"

namespace {

using namespace hemirad::test;

std::size_t lines(const std::string& text) { return std::size_t(std::count(text.begin(), text.end(), '\n')); }

// A run that must be refused as bad input: exit 2, one line on stderr holding `words`.
void expect_refused(const RunResult& r, const std::string& words) {
    INFO("exit " << r.code << ", stderr: " << r.err);
    CHECK(r.code == 2);
    CHECK(lines(r.err) == 1);
    CHECK(r.err.find(words) != std::string::npos);
}

// The hemirad executable with `args`, each quoted, for a shell script.
std::string hemirad_command(const std::vector<std::string>& args) {
    std::string command = shell_quote(HEMIRAD_EXE);
    for (const std::string& a : args) command += " " + shell_quote(a);
    return command;
}

// The closed room (scenes/closed_room.gltf) with `edit` applied, written as dir/name.
template <class Edit>
fs::path closed_room_with(const TempDir& dir, const std::string& name, Edit edit) {
    json g = read_json(kClosedRoom);
    edit(g);
    const fs::path file = dir / name;
    write_json(file, g);
    return file;
}

// The bytes of every regular file below `dir`, by path: to show that a refused bake changed none.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
    std::map<std::string, std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(dir))
        if (e.is_regular_file()) files[e.path().string()] = read_text(e.path());
    return files;
}

}  // namespace

TEST_CASE("hostile input: no output replaces the scene or a file it reads, however it is named", "[hostile][outputs]") {
    TempDir dir;
    bake_ok(dir, kClosedRoom, dir / "out");

    SECTION("re-baking out/baked.gltf into out/") {
        const auto before = snapshot(dir.path());
        expect_refused(run_hemirad(dir, bake_args(dir / "out" / "baked.gltf", dir / "out")), "is the scene being baked");
        CHECK(snapshot(dir.path()) == before);
    }
    SECTION("the same scene through a link, into its own folder named another way") {
        fs::create_directories(dir / "links");
        fs::create_symlink(dir / "out" / "baked.gltf", dir / "links" / "scene.gltf");
        fs::create_symlink(dir / "out", dir / "out_link");
        const auto before = snapshot(dir / "out");
        expect_refused(run_hemirad(dir, bake_args(dir / "links" / "scene.gltf", dir / "out")), "the scene being baked");
        expect_refused(run_hemirad(dir, bake_args(dir / "out" / "baked.gltf", dir / "out_link")), "the scene being baked");
        CHECK(snapshot(dir / "out") == before);
    }
    SECTION("a texture named render.png, baked into the scene's own folder") {
        fs::create_directories(dir / "scene");
        const fs::path scene = closed_room_with(dir, "scene/room.gltf", [](json& g) { g["images"] = {{{"uri", "render.png"}}}; });
        write_text(dir / "scene" / "render.png", "the user's texture");
        const auto before = snapshot(dir / "scene");
        expect_refused(run_hemirad(dir, bake_args(scene, dir / "scene")), "render.png', a file the scene reads");
        CHECK(snapshot(dir / "scene") == before);
    }
    SECTION("a file the scene reads, hard-linked where an output goes") {
        const fs::path scene = closed_room_with(dir, "room.gltf", [](json& g) { g["images"] = {{{"uri", "tex%20ture.png"}}}; });
        write_text(dir / "tex ture.png", "the user's texture");
        fs::create_directories(dir / "elsewhere");
        fs::create_hard_link(dir / "tex ture.png", dir / "elsewhere" / "report.json");
        expect_refused(run_hemirad(dir, bake_args(scene, dir / "elsewhere")), "tex ture.png");
        CHECK(read_text(dir / "tex ture.png") == "the user's texture");
    }
    SECTION("an image where --preview-every writes its frames") {
        fs::create_directories(dir / "out" / "preview");
        write_text(dir / "out" / "preview" / "pass_000001.png", "the user's image");
        const fs::path scene = closed_room_with(dir, "room.gltf", [](json& g) {
            g["images"] = {{{"uri", "out/preview/pass_000001.png"}}};
        });
        expect_refused(run_hemirad(dir, bake_args(scene, dir / "out", concat(kFast, {"--preview-every", "1"}))),
                       "--preview-every writes its frames there");
        CHECK(read_text(dir / "out" / "preview" / "pass_000001.png") == "the user's image");
    }
    SECTION("outputs that only share a name with an input elsewhere are written") {
        const fs::path scene = closed_room_with(dir, "room.gltf", [](json& g) { g["images"] = {{{"uri", "render.png"}}}; });
        write_text(dir / "render.png", "the user's texture");
        bake_ok(dir, scene, dir / "out");
        CHECK(read_text(dir / "render.png") == "the user's texture");
    }
}

namespace {

// A scene of one emissive triangle whose POSITION accessor is sparse over zeros with `count`
// elements: 1,966 bytes that asked the loader for count × 36 bytes and more.
json sparse_positions(double count) {
    json g = json::parse(R"({
      "asset": {"version": "2.0"},
      "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
      "materials": [{"emissiveFactor": [1, 1, 1]}],
      "buffers": [{"byteLength": 16, "uri": "data:application/octet-stream;base64,AAAAAAAAgD8AAAAAAAAAAA=="}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 4}, {"buffer": 0, "byteOffset": 4, "byteLength": 12}],
      "accessors": [{"componentType": 5126, "type": "VEC3", "min": [0, 0, 0], "max": [1, 0, 0],
                     "sparse": {"count": 1, "indices": {"bufferView": 0, "componentType": 5125}, "values": {"bufferView": 1}}}]
    })");
    // One sparse index (0, an unsigned int) and its value (1, 0, 0): the 16 bytes of the buffer.
    g["accessors"][0]["count"] = std::uint64_t(count);
    return g;
}

// Runs hemirad under a guard: a run the fix refuses from the JSON takes a second; one that
// tries takes minutes (113 s for the sparse file), which `timeout` turns into exit 124.
RunResult guarded(const TempDir& dir, const std::vector<std::string>& args, const std::string& env = "") {
    return run_hemirad(dir, args, env + "timeout 100 ");
}

}  // namespace

TEST_CASE("hostile input: a small file that asks for more memory than allowed is refused from its JSON", "[hostile][memory]") {
    TempDir dir;
    SECTION("a sparse accessor of 3e8 positions over zeros, under --max-memory 2G") {
        const fs::path file = dir / "sparse.gltf";
        write_json(file, sparse_positions(3e8));
        CHECK(fs::file_size(file) < 4096);
        const RunResult r = guarded(dir, bake_args(file, dir / "never", concat(kFast, {"--max-memory", "2G"})));
        expect_refused(r, "loading it would need about");
        CHECK(r.err.find("sparse accessors made whole") != std::string::npos);
        CHECK(r.err.find("--max-memory allows") != std::string::npos);
        CHECK(!fs::exists(dir / "never"));
    }
    SECTION("one index accessor in 600 primitives on 3,000 nodes: 1.08e9 triangles, against the machine") {
        // 600 triangles of indices 0, 1, 2 over three positions: 7,200 bytes.
        json g = json::parse(R"({"asset": {"version": "2.0"}, "materials": [{"emissiveFactor": [1, 1, 1]}]})");
        std::string indices;
        for (int t = 0; t < 600; ++t)
            for (std::uint32_t i : {0u, 1u, 2u}) indices.append(reinterpret_cast<const char*>(&i), 4);
        const float positions[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        write_text(dir / "data.bin", indices + std::string(reinterpret_cast<const char*>(positions), sizeof positions));
        g["buffers"] = {{{"uri", "data.bin"}, {"byteLength", indices.size() + sizeof positions}}};
        g["bufferViews"] = {{{"buffer", 0}, {"byteLength", indices.size()}},
                            {{"buffer", 0}, {"byteOffset", indices.size()}, {"byteLength", sizeof positions}}};
        g["accessors"] = {{{"bufferView", 0}, {"componentType", 5125}, {"type", "SCALAR"}, {"count", 1800}},
                          {{"bufferView", 1}, {"componentType", 5126}, {"type", "VEC3"}, {"count", 3},
                           {"min", {0, 0, 0}}, {"max", {1, 1, 0}}}};
        json primitives = json::array();
        for (int p = 0; p < 600; ++p) primitives.push_back({{"attributes", {{"POSITION", 1}}}, {"indices", 0}, {"material", 0}});
        g["meshes"] = {{{"primitives", primitives}}};
        json nodes = json::array(), roots = json::array();
        for (int n = 0; n < 3000; ++n) {
            nodes.push_back({{"mesh", 0}, {"translation", {0, 0, n}}});
            roots.push_back(n);
        }
        g["nodes"] = nodes;
        g["scenes"] = {{{"nodes", roots}}};
        const fs::path file = dir / "instanced.gltf";
        write_json(file, g);
        const RunResult r = guarded(dir, bake_args(file, dir / "never"));
        expect_refused(r, "1.08e+09 triangles after instancing");
        CHECK(r.err.find("this machine has") != std::string::npos);
    }
    SECTION("a meshopt fallback buffer of 3 GiB declared in a 2 KB file, under --max-memory 2G") {
        json g = sparse_positions(3);
        g["extensionsUsed"] = {"EXT_meshopt_compression"};
        g["extensionsRequired"] = {"EXT_meshopt_compression"};
        g["buffers"].push_back({{"byteLength", std::uint64_t{3221225472}}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
        g["bufferViews"].push_back({{"buffer", 1},
                                    {"byteLength", std::uint64_t{3221225472}},
                                    {"extensions",
                                     {{"EXT_meshopt_compression",
                                       {{"buffer", 0}, {"byteLength", 16}, {"byteStride", 4}, {"count", 805306368},
                                        {"mode", "ATTRIBUTES"}}}}}});
        const fs::path file = dir / "fallback.gltf";
        write_json(file, g);
        const RunResult r = guarded(dir, bake_args(file, dir / "never", concat(kFast, {"--max-memory", "2G"})));
        expect_refused(r, "decompressed buffers 3.22 GB");
    }
    SECTION("an integer of 2^32 + 12 in an extension hemirad reads is refused, not cut to 12") {
        json g = sparse_positions(3);
        g["extensionsUsed"] = {"EXT_meshopt_compression"};
        g["bufferViews"].push_back({{"buffer", 0},
                                    {"byteLength", 12},
                                    {"extensions",
                                     {{"EXT_meshopt_compression",
                                       {{"buffer", 0}, {"byteLength", 16}, {"byteStride", std::uint64_t{4294967308}},
                                        {"count", 1}, {"mode", "ATTRIBUTES"}}}}}});
        const fs::path file = dir / "stride.gltf";
        write_json(file, g);
        expect_refused(guarded(dir, bake_args(file, dir / "never")),
                       "bufferViews[2].extensions.EXT_meshopt_compression.byteStride is 4294967308, too large");
        // An application's own 64-bit number in extras is its business: the scene bakes.
        const fs::path extras = closed_room_with(dir, "extras.gltf", [](json& room) {
            room["nodes"][0]["extras"] = {{"id", std::uint64_t{1} << 40}};
        });
        bake_ok(dir, extras, dir / "out");
    }
    SECTION("--resume names a 6 GiB file: refused from its head, never read whole") {
        // Under a 3 GB address space, reading it whole fails as out of memory (exit 1).
        const fs::path big = dir / "big.checkpoint";
        write_text(big, std::string("hemirad checkpoint\n") + std::string("\xff\x00\x00\x00", 4));  // no such format
        fs::resize_file(big, std::uintmax_t{6} << 30);  // sparse: no disk space
        const RunResult r = run_hemirad(dir,
                                        bake_args(kClosedRoom, dir / "never",
                                                  concat(kFast, {"--device", "ref", "--solver", "progressive",
                                                                 "--resume", big.string()})),
                                        "ulimit -v 3000000; ");
        expect_refused(r, "checkpoint format 255");
    }
}

TEST_CASE("hostile input: --image-width up to 16384 is estimated at what the render allocates", "[hostile][memory]") {
    TempDir dir;
    // The refusal that follows the memory plan (--preview-every with the matrix solver) shows the
    // plan let 16384 × 12288 pass within 8 GB: 201 M pixels at 20 bytes (the image and the
    // exposure's luminances) is 4 GB. It was estimated at 320 bytes a pixel: 64 GB.
    const std::vector<std::string> fast = {"--hemicube", "32", "--patch-size", "1.0", "--element-size", "0.5",
                                           "--max-passes", "200", "--quiet", "--image-width", "16384"};
    const RunResult fits = run_hemirad(
        dir, bake_args(kClosedRoom, dir / "never",
                       concat(fast, {"--max-memory", "8G", "--solver", "matrix", "--preview-every", "1"})));
    expect_refused(fits, "--preview-every shows the passes of the progressive solver");
    const RunResult refused =
        run_hemirad(dir, bake_args(kClosedRoom, dir / "never", concat(fast, {"--max-memory", "3G"})));
    expect_refused(refused, "output 4.0");
}

TEST_CASE("hostile input: a kernel knob inside its documented range but beyond what the device runs is exit 2, never a crash", "[hostile][opencl]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    TempDir dir;
    // PoCL ran raster_records' work-groups on 8 MiB thread stacks: 1024 work-items of 12.5 KB
    // each crashed (SIGSEGV), under --device auto before its first-shot check could fall back.
    // Setup's groups of 1024 crashed it too (768 ran).
    for (const std::string knob : {"HEMIRAD_RASTER_WG=1024", "HEMIRAD_WG=1024"})
        for (const std::string device : {"opencl", "auto"}) {
            INFO(knob << " --device " << device);
            const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, dir / "never", concat(kFast, {"--device", device})),
                                            "HEMIRAD_OPENCL_OPTIONS=-D" + knob + " ");
            const hemirad::ocl::DeviceInfo& first = hemirad::ocl::list_devices().front();
            if (first.type != "cpu") {  // a GPU runs neither knob's kernel from the stack
                CHECK(r.code != 139);
                continue;
            }
            expect_refused(r, knob);
            CHECK(r.err.find("work-items per group") != std::string::npos);
        }
}

namespace {

// A long bake (a preview every pass) into dir/out, sent `signal` once its first preview exists;
// `env --default-signal` undoes the ignoring of SIGINT and SIGQUIT a shell gives background jobs.
RunResult signalled_bake(const TempDir& dir, const std::string& signal) {
    std::string script = "env --default-signal=INT,QUIT " +
                         hemirad_command({"bake", kClosedRoom.string(), "-o", "out", "--hemicube", "256", "--threshold",
                                          "1e-7", "--preview-every", "1", "--image-width", "32", "--quiet"});
    script += " & pid=$!; i=0; while [ -z \"$(ls out/preview 2>/dev/null)\" ] && [ $i -lt 400 ]; do sleep 0.05; i=$((i+1)); "
              "done; kill -" + signal + " $pid && echo signal-sent; wait $pid";
    return run_shell(dir, script);
}

int signal_number(const std::string& name) {
    const std::map<std::string, int> numbers = {{"QUIT", SIGQUIT}, {"USR1", SIGUSR1}, {"USR2", SIGUSR2},
                                                {"ALRM", SIGALRM}, {"XCPU", SIGXCPU}, {"VTALRM", SIGVTALRM},
                                                {"PROF", SIGPROF}, {"XFSZ", SIGXFSZ}, {"PIPE", SIGPIPE}};
    return numbers.at(name);
}

}  // namespace

TEST_CASE("hostile input: every signal that would end a bake stops it cleanly: exit 128 + the signal, nothing left", "[hostile][signals]") {
    // SIGUSR1 was kept by LLVM inside PoCL's compiler (the bake went on); the others killed the
    // process and left .hemirad-tmp-PID and the preview frames.
    for (const std::string signal : {"QUIT", "USR1", "USR2", "ALRM", "XCPU", "VTALRM", "PROF", "XFSZ", "PIPE"}) {
        INFO("SIG" << signal);
        TempDir dir;
        const RunResult r = signalled_bake(dir, signal);
        INFO("stderr: " << r.err);
        REQUIRE(r.out.find("signal-sent") != std::string::npos);
        CHECK(r.code == 128 + signal_number(signal));
        CHECK(r.err.find("stopped by SIG" + signal + "; no output written") != std::string::npos);
        CHECK(!fs::exists(dir / "out"));
    }
}

TEST_CASE("hostile input: a reader that goes away (SIGPIPE on --progress) stops the bake cleanly", "[hostile][signals]") {
    TempDir dir;
    // stderr into a pipe whose reader takes one byte and leaves: the next progress line is SIGPIPE.
    const std::string bake = hemirad_command({"bake", kClosedRoom.string(), "-o", "out", "--hemicube", "256", "--threshold",
                                              "1e-7", "--image-width", "32", "--solver", "progressive", "--progress"});
    const RunResult r = run_shell(dir, "bash -c " + shell_quote(bake + " 2>&1 | head -c 1 >/dev/null; echo status=${PIPESTATUS[0]}"));
    INFO("stdout: " << r.out << " stderr: " << r.err);
    CHECK(r.out.find("status=141") != std::string::npos);
    CHECK(!fs::exists(dir / "out"));
}

TEST_CASE("hostile input: a stop while the bake polls nothing (a large render) ends within a second, nothing left", "[hostile][signals]") {
    TempDir dir;
    fs::create_directories(dir / "mine");
    write_text(dir / "mine" / "notes.txt", "keep\n");
    // The solve is over in a second; rendering and writing 8192 × 6144 pixels take many more, with
    // no check for a stop inside: the watchdog (core/cancel.h) ends the process.
    // Not --quiet: the bake's "form factors on" line says the solve has begun.
    std::string script = hemirad_command(bake_args(kClosedRoom, "mine",
                                                   {"--hemicube", "32", "--patch-size", "1.0", "--element-size", "0.5",
                                                    "--max-passes", "200", "--image-width", "8192"}));
    script += " 2>err.txt & pid=$!; i=0; while ! grep -q 'form factors' err.txt 2>/dev/null && [ $i -lt 600 ]; do sleep 0.05; "
              "i=$((i+1)); done; sleep 2; start=$(date +%s%N); kill -TERM $pid; wait $pid; code=$?; "
              "end=$(date +%s%N); echo code=$code ms=$(( (end - start) / 1000000 )); cat err.txt";
    const RunResult r = run_shell(dir, script);
    INFO("stdout: " << r.out);
    REQUIRE(r.out.find("code=") != std::string::npos);
    CHECK(r.out.find("code=130") != std::string::npos);
    const long ms = std::stol(r.out.substr(r.out.find("ms=") + 3));
    // The grace is 0.5 s; a busy machine may add to it, far less than the render's seconds.
    CHECK(ms < 3000);
    std::set<std::string> left;
    for (const auto& e : fs::directory_iterator(dir / "mine")) left.insert(e.path().filename().string());
    CHECK(left == std::set<std::string>{"notes.txt"});
}

TEST_CASE("hostile input: a lamp the bake cannot see is named, and with no light left the bake is refused", "[hostile][lights]") {
    TempDir dir;
    // The panel's material cut away whole by alphaMode MASK: alpha 0.2 under a cutoff of 0.5.
    const auto mask_the_lamp = [](json& g) {
        json& light = g["materials"][3];
        light["alphaMode"] = "MASK";
        light["alphaCutoff"] = 0.5;
        light["pbrMetallicRoughness"]["baseColorFactor"] = {0.8, 0.8, 0.8, 0.2};
    };
    const fs::path masked = closed_room_with(dir, "masked.gltf", mask_the_lamp);
    expect_refused(run_hemirad(dir, bake_args(masked, dir / "never")),
                   "nothing gives light, the bake would be black: material 'light' emits, but its 2 triangles give the "
                   "bake no light: its surfaces are cut away by alphaMode MASK");
    CHECK(!fs::exists(dir / "never"));
    // With a second, visible lamp (the floor glows) it bakes, and says which lamp it could not see.
    const fs::path two = closed_room_with(dir, "two.gltf", [&](json& g) {
        mask_the_lamp(g);
        g["materials"][1]["emissiveFactor"] = {0.1, 0.1, 0.1};
    });
    const json report = bake_ok(dir, two, dir / "out");
    bool named = false;
    for (const auto& w : report.at("warnings"))
        named = named || w.get<std::string>().find("material 'light' emits, but its 2 triangles give the bake no light: "
                                                   "its surfaces are cut away by alphaMode MASK") != std::string::npos;
    CHECK(named);
}

TEST_CASE("hostile input: empty and hex values of --sun, --sky and --max-memory are exit 2", "[hostile][options]") {
    TempDir dir;
    for (const auto& args : std::vector<std::vector<std::string>>{{"--sun", ""},
                                                                  {"--sky", ""},
                                                                  {"--max-memory", ""},
                                                                  {"--camera", ""},
                                                                  {"--sky", "0x10"},
                                                                  {"--sky", " 1"},
                                                                  {"--sun", "0x10,40,100"},
                                                                  {"--sun", "10,4e1,inf"},
                                                                  {"--max-memory", "0x10G"}}) {
        INFO(args[0] << " '" << args[1] << "'");
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, dir / "never", concat(kFast, args)));
        expect_refused(r, args[0]);
        CHECK(!fs::exists(dir / "never"));
    }
}

TEST_CASE("hostile input: a disk that fills while previews are written is an error, nothing left", "[hostile][outputs]") {
    TempDir dir;
    // A 100 KB tmpfs in a mount namespace of the test's own (root only; skipped elsewhere).
    const std::string bake = hemirad_command({"bake", kClosedRoom.string(), "-o", "full/out", "--hemicube", "64",
                                              "--threshold", "1e-7", "--image-width", "128", "--preview-every", "1",
                                              "--quiet"});
    const RunResult r = run_shell(
        dir, "mkdir full && unshare -m sh -c " +
                 shell_quote("mount -t tmpfs -o size=100k tmpfs full || exit 77; " + bake +
                             "; echo code=$?; echo entries=$(ls -A full | wc -l)"));
    const Presence tmpfs{"a 100 KB tmpfs", r.code != 77 && r.out.find("entries=") != std::string::npos,
                         "cannot mount one here (needs root): " + r.err};
    HEMIRAD_SKIP_ABSENT(tmpfs);
    INFO("stdout: " << r.out << " stderr: " << r.err);
    CHECK(r.out.find("code=1") != std::string::npos);
    CHECK(r.err.find("written incompletely") != std::string::npos);
    CHECK(r.err.find("is the disk full?") != std::string::npos);
    CHECK(r.out.find("entries=0") != std::string::npos);
}

TEST_CASE("hostile input: 100,000 point lights say how long they will take before starting, show progress and stop at once", "[hostile][lights]") {
    TempDir dir;
    // An 11 MB file of one light placed by 100,000 nodes: 200,000 hemicubes, minutes on 2 cores.
    // It ran past 120 s with no estimate and no progress, and held every row at once.
    const fs::path file = closed_room_with(dir, "lights.gltf", [](json& g) {
        g["extensionsUsed"] = {"KHR_lights_punctual"};
        g["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 0.001}}}}}}};
        for (int i = 0; i < 100000; ++i) {
            g["scenes"][0]["nodes"].push_back(g["nodes"].size());
            g["nodes"].push_back({{"translation", {-1.5 + 3.0 * (i % 400) / 400.0, 2.2, -2.0 + 4.0 * (i / 400) / 250.0}},
                                  {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
        }
    });
    const std::string script =
        hemirad_command({"bake", file.string(), "-o", "out", "--progress"}) +
        " 2>err.txt & pid=$!; i=0; while ! grep -q \" / 200000 \" err.txt 2>/dev/null && [ $i -lt 1200 ]; do "
        "sleep 0.05; i=$((i+1)); done; kill -TERM $pid; wait $pid; echo code=$?; cat err.txt";
    const RunResult r = run_shell(dir, script);
    INFO("stdout: " << r.out);
    CHECK(r.out.find("code=130") != std::string::npos);
    const std::size_t warned = r.out.find("this bake is expected to take ");
    const std::size_t started = r.out.find("form factors on");
    REQUIRE(warned != std::string::npos);
    CHECK(warned < started);
    CHECK(r.out.find("min (") != std::string::npos);  // minutes, not seconds
    CHECK(r.out.find("lights' hemicubes", warned) != std::string::npos);
    // Progress, a batch at a time. (The script waits for its first line by " / 200000 ": the
    // warning names the lights' hemicubes too, and a stop right after it would show no progress.)
    CHECK(r.out.find("lights' hemicubes 256 / 200000") != std::string::npos);
    CHECK(!fs::exists(dir / "out"));
}

TEST_CASE("a bake's time warning says 'about' where it counts the solve and 'more than' where it does not",
          "[cli][eta]") {
    // The warning counted the final gather and not the progressive solve, and still said "about":
    // the ww2 city's "about 61 s" took 6 minutes, 3 of them solving. The Cornell box with a gather
    // of N 1024 is said to take about 3 minutes; each bake is stopped once its solve starts.
    TempDir dir;
    for (const std::string solver : {"matrix", "progressive"}) {
        const std::string script =
            hemirad_command(
                bake_args(kCornellBox, dir / solver, {"--gather", "1024", "--solver", solver, "--no-checkpoint"})) +
            " 2>" + solver + ".txt & pid=$!; i=0; while ! grep -q \"form factors on\" " + solver +
            ".txt 2>/dev/null && [ $i -lt 1200 ]; do sleep 0.05; i=$((i+1)); done; kill -TERM $pid; wait $pid; "
            "echo code=$?; cat " +
            solver + ".txt";
        const RunResult r = run_shell(dir, script);
        INFO("solver " << solver << ", stdout: " << r.out);
        CHECK(r.out.find("code=130") != std::string::npos);
        const std::size_t warned = r.out.find("this bake is expected to take ");
        REQUIRE(warned != std::string::npos);
        CHECK(warned < r.out.find("form factors on"));
        if (solver == "matrix") {
            CHECK(r.out.find("expected to take about ") != std::string::npos);
            CHECK(r.out.find("(solve ") != std::string::npos);
            CHECK(r.out.find("besides the progressive solve") == std::string::npos);
        } else {
            CHECK(r.out.find("expected to take more than ") != std::string::npos);
            CHECK(r.out.find("besides the progressive solve, whose passes are not known before it runs") !=
                  std::string::npos);
        }
        CHECK(!fs::exists(dir / solver));
    }
}
