// End-to-end tests of the hemirad executable: every test runs the real binary through
// /bin/sh in a fresh temporary directory and checks its files, report and exit code against
// facts computed here, independently of the library (DESIGN.md "Interface").
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <catch2/catch.hpp>

#include "backends.h"
#include "cli_support.h"
#include "cl/runtime.h"
#include "bench/room_reference.h"
#include "core/quality.h"
#include <nlohmann/json.hpp>
#include <OpenImageIO/imageio.h>
#include <tiny_gltf.h>

namespace {

using namespace hemirad::test;

std::set<std::string> listing(const fs::path& dir) {
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
    return names;
}

// Names of the file's nodes that hold a mesh, as DESIGN.md defines them: node name, else mesh
// name, else node<index>; in node order, reached from the default scene through children.
std::vector<std::string> expected_mesh_names(const json& gltf) {
    const json& nodes = gltf.at("nodes");
    std::vector<bool> reached(nodes.size(), false);
    const int scene = gltf.value("scene", 0);
    std::vector<int> stack;
    for (const auto& n : gltf.at("scenes").at(scene).at("nodes")) stack.push_back(n.get<int>());
    while (!stack.empty()) {
        const int n = stack.back();
        stack.pop_back();
        reached.at(std::size_t(n)) = true;
        if (nodes[std::size_t(n)].contains("children"))
            for (const auto& c : nodes[std::size_t(n)]["children"]) stack.push_back(c.get<int>());
    }
    std::vector<std::string> names;
    for (std::size_t i = 0; i < nodes.size(); ++i) {
        const json& node = nodes[i];
        if (!reached[i] || !node.contains("mesh")) continue;
        std::string name = node.value("name", "");
        if (name.empty()) name = gltf.at("meshes").at(node["mesh"].get<std::size_t>()).value("name", "");
        if (name.empty()) name = "node" + std::to_string(i);
        names.push_back(name);
    }
    return names;
}

std::vector<std::string> sorted(std::vector<std::string> v) {
    std::sort(v.begin(), v.end());
    return v;
}

std::vector<std::string> report_mesh_names(const json& report) {
    std::vector<std::string> names;
    for (const auto& m : report.at("meshes")) names.push_back(m.at("name").get<std::string>());
    return names;
}

// Every number anywhere in `j` is finite.
bool all_numbers_finite(const json& j) {
    if (j.is_number()) return std::isfinite(j.get<double>());
    if (j.is_array() || j.is_object()) {
        for (const auto& v : j)
            if (!all_numbers_finite(v)) return false;
    }
    return true;
}

int count_lines(const std::string& text) { return int(std::count(text.begin(), text.end(), '\n')); }

// The error message is one line (ending in '\n', no other newline, not blank).
void check_one_line(const std::string& err) {
    INFO("stderr: [" << err << "]");
    CHECK(count_lines(err) == 1);
    CHECK(!err.empty());
    CHECK(err.back() == '\n');
    CHECK(err.find_first_not_of(" \t\r\n") != std::string::npos);
}

// A bad-input run: exit 2, one line on stderr naming `token`, and `out` not created. `env`:
// environment assignments (or a command such as kNoHang) in front, as run_hemirad takes them.
RunResult expect_bad_input(const TempDir& dir, const std::vector<std::string>& args, const fs::path& out,
                           const std::string& token, const std::string& env = "") {
    REQUIRE(!fs::exists(out));
    const RunResult r = run_hemirad(dir, args, env);
    INFO("stderr: [" << r.err << "]");
    CHECK(r.code == 2);
    check_one_line(r.err);
    CHECK(r.err.find(token) != std::string::npos);
    CHECK(!fs::exists(out));
    CHECK(r.out.empty());
    return r;
}

// closed_room.gltf scaled by `s` about the origin: a new root node with scale [s, s, s] whose
// children are the scene's old roots; the scene holds only the new node.
json scaled_scene(const json& original, double s) {
    json g = original;
    json root = {{"name", "scale_root"}, {"scale", {s, s, s}}, {"children", g["scenes"][0]["nodes"]}};
    g["nodes"].push_back(root);
    g["scenes"][0]["nodes"] = json::array({g["nodes"].size() - 1});
    return g;
}

// The camera's aspect ratio from the .gltf JSON (closed_room has one perspective camera).
double camera_aspect(const json& gltf) {
    return gltf.at("cameras").at(0).at("perspective").at("aspectRatio").get<double>();
}

}  // namespace

TEST_CASE("bake writes exactly the five output files and a complete report", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "out";
    const json report = bake_ok(dir, kClosedRoom, out, concat(kFast, {"--threshold", "0.002", "--seed", "3"}));

    CHECK(listing(out) == std::set<std::string>{"report.json", "baked.gltf", "baked.bin", "render.exr", "render.png"});
    CHECK(all_numbers_finite(report));

    for (const char* key : {"version", "scene", "device", "settings", "counts", "passes", "converged", "energy",
                            "effects", "timings_s", "meshes"}) {
        INFO("key " << key);
        CHECK(report.contains(key));
    }
    CHECK(report.at("version").is_string());
    CHECK(!report.at("version").get<std::string>().empty());
    CHECK(report.at("scene").get<std::string>().find("closed_room.gltf") != std::string::npos);

    const json& device = report.at("device");
    CHECK(device.at("backend") == (hemirad::ocl::list_devices().empty() ? "ref" : "opencl"));  // auto
    CHECK(device.at("platform").is_string());
    CHECK(device.at("name").is_string());

    const json& settings = report.at("settings");
    CHECK(settings.at("hemicube").get<int>() == 32);
    CHECK(settings.at("patch_size").get<double>() == Approx(1.0));
    CHECK(settings.at("element_size").get<double>() == Approx(0.5));
    CHECK(settings.at("threshold").get<double>() == Approx(0.002));
    CHECK(settings.at("seed").get<std::uint64_t>() == 3u);

    const json& counts = report.at("counts");
    CHECK(counts.at("triangles").get<long>() > 0);
    CHECK(counts.at("patches").get<long>() > 0);
    CHECK(counts.at("elements").get<long>() >= counts.at("patches").get<long>());

    CHECK(report.at("passes").is_number_integer());
    CHECK(report.at("passes").get<long>() > 0);
    CHECK(report.at("passes").get<long>() <= 200);
    CHECK(report.at("converged").is_boolean());

    const json& energy = report.at("energy");
    const double emitted = energy.at("emitted").get<double>();
    const double absorbed = energy.at("absorbed").get<double>();
    const double escaped = energy.at("escaped").get<double>();
    const double unshot = energy.at("unshot").get<double>();
    CHECK(emitted > 0.0);
    CHECK(absorbed > 0.0);
    CHECK(unshot >= 0.0);
    CHECK(std::abs(emitted - (absorbed + escaped + unshot)) <= 1e-6 * std::abs(emitted));
    // closed_room's light: a 1 m x 1 m panel of radiance 10 (emissiveFactor 1 x strength 10),
    // so the emitted power, in the report's radiosity-times-area units, is 10 x 1 m^2.
    CHECK(emitted == Approx(10.0).epsilon(1e-6));

    const json& effects = report.at("effects");
    REQUIRE(effects.is_object());
    CHECK(effects.at("occlusion").at("on").is_boolean());
    CHECK(effects.at("occlusion").at("why").is_string());
    for (const auto& [name, effect] : effects.items()) {
        INFO("effect " << name);
        CHECK(effect.at("on").is_boolean());
        CHECK(effect.at("why").is_string());
    }

    const json& timings = report.at("timings_s");
    for (const char* key : {"load", "mesh", "formfactors", "solve", "output", "total"}) {
        INFO("timing " << key);
        REQUIRE(timings.contains(key));
        CHECK(timings.at(key).get<double>() >= 0.0);
    }

    const json gltf = read_json(kClosedRoom);
    const std::vector<std::string> expected = expected_mesh_names(gltf);
    REQUIRE(expected.size() == 8);  // closed_room: floor, ceiling, four walls, light, cube
    CHECK(sorted(report_mesh_names(report)) == sorted(expected));
    double total_area = 0.0;
    for (const auto& m : report.at("meshes")) {
        INFO("mesh " << m.at("name"));
        CHECK(m.at("area").get<double>() > 0.0);
        total_area += m.at("area").get<double>();
        REQUIRE(m.at("radiosity").size() == 3);
        REQUIRE(m.at("irradiance").size() == 3);
        for (int c = 0; c < 3; ++c) {
            CHECK(m.at("radiosity")[c].get<double>() >= 0.0);
            CHECK(m.at("irradiance")[c].get<double>() >= 0.0);
        }
        if (m.at("name") == "light") CHECK(m.at("radiosity")[0].get<double>() >= 10.0);
        if (m.at("name") == "floor") CHECK(m.at("area").get<double>() == Approx(4.0 * 5.0).epsilon(1e-9));
    }
    // Room 4 x 2.5 x 5 m: floor + ceiling 40, walls 2 x 10 + 2 x 12.5, light 1, cube 5 faces of 0.64.
    CHECK(total_area == Approx(40.0 + 20.0 + 25.0 + 1.0 + 5 * 0.64).epsilon(1e-6));
}

TEST_CASE("baked.gltf is a valid glTF with one node per mesh node and finite COLOR_0", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "out";
    bake_ok(dir, kClosedRoom, out, {"--output-mode", "radiosity"});

    const std::string baked_text = read_text(out / "baked.gltf");
    CHECK(baked_text.find(".hemirad-tmp") == std::string::npos);  // no staging path leaked

    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    const bool ok = loader.LoadASCIIFromFile(&model, &err, &warn, (out / "baked.gltf").string());
    INFO("tinygltf error: " << err << " warning: " << warn);
    REQUIRE(ok);
    CHECK(err.empty());
    CHECK(model.asset.version == "2.0");
    REQUIRE(model.buffers.size() == 1);
    CHECK(model.buffers[0].uri == "baked.bin");

    const std::vector<std::string> expected = expected_mesh_names(read_json(kClosedRoom));
    std::vector<std::string> names;
    for (const auto& node : model.nodes) {
        CHECK(node.mesh >= 0);
        names.push_back(node.name);
    }
    CHECK(sorted(names) == sorted(expected));

    int colour_accessors = 0;
    for (const auto& mesh : model.meshes) {
        for (const auto& prim : mesh.primitives) {
            REQUIRE(prim.attributes.count("POSITION") == 1);
            REQUIRE(prim.attributes.count("COLOR_0") == 1);
            const tinygltf::Accessor& pos = model.accessors.at(std::size_t(prim.attributes.at("POSITION")));
            const tinygltf::Accessor& col = model.accessors.at(std::size_t(prim.attributes.at("COLOR_0")));
            CHECK(col.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT);
            CHECK(col.type == TINYGLTF_TYPE_VEC3);
            CHECK(col.count == pos.count);
            CHECK(col.count > 0);
            CHECK(!col.sparse.isSparse);
            REQUIRE(col.bufferView >= 0);
            const tinygltf::BufferView& view = model.bufferViews.at(std::size_t(col.bufferView));
            const tinygltf::Buffer& buffer = model.buffers.at(std::size_t(view.buffer));
            const std::size_t stride = view.byteStride != 0 ? view.byteStride : 3 * sizeof(float);
            const std::size_t start = view.byteOffset + col.byteOffset;
            REQUIRE(start + (col.count - 1) * stride + 3 * sizeof(float) <= view.byteOffset + view.byteLength);
            REQUIRE(view.byteOffset + view.byteLength <= buffer.data.size());
            bool finite = true, non_negative = true, some_light = false;
            for (std::size_t i = 0; i < col.count; ++i) {
                float rgb[3];
                std::memcpy(rgb, buffer.data.data() + start + i * stride, sizeof rgb);
                for (float v : rgb) {
                    finite = finite && std::isfinite(v);
                    non_negative = non_negative && v >= 0.0f;
                    some_light = some_light || v > 0.0f;
                }
            }
            INFO("mesh " << mesh.name);
            CHECK(finite);
            CHECK(non_negative);
            CHECK(some_light);
            ++colour_accessors;
        }
    }
    CHECK(colour_accessors >= int(expected.size()));
}

TEST_CASE("render.png and render.exr have the requested size and the camera aspect", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "out";
    const json report = bake_ok(dir, kClosedRoom, out);

    const json gltf = read_json(kClosedRoom);
    const double aspect = camera_aspect(gltf);
    REQUIRE(aspect == Approx(4.0 / 3.0));
    const int width = 64;
    const int height = int(std::lround(width / aspect));
    REQUIRE(height == 48);

    const ImageData png = read_image(out / "render.png");
    CHECK(png.width == width);
    CHECK(png.height == height);
    REQUIRE(png.channels >= 3);
    float brightest = 0.0f;
    for (std::size_t p = 0; p < png.pixels.size(); p += std::size_t(png.channels))
        for (int c = 0; c < 3; ++c) brightest = std::max(brightest, png.pixels[p + std::size_t(c)]);
    CHECK(brightest > 0.0f);  // not all black

    const ImageData exr = read_image(out / "render.exr");
    CHECK(exr.width == width);
    CHECK(exr.height == height);
    REQUIRE(exr.channels >= 3);
    bool finite = true, non_negative = true;
    float exr_brightest = 0.0f;
    for (float v : exr.pixels) {
        finite = finite && std::isfinite(v);
        non_negative = non_negative && v >= 0.0f;
        exr_brightest = std::max(exr_brightest, v);
    }
    CHECK(finite);
    CHECK(non_negative);
    CHECK(exr_brightest > 0.0f);

    // The report states the size it rendered at.
    CHECK(report.at("settings").at("image") == json::array({width, height}));

    SECTION("the Cornell box camera is square") {
        const fs::path out2 = dir / "cornell";
        bake_ok(dir, kCornellBox, out2,
                {"--hemicube", "32", "--patch-size", "0.15", "--element-size", "0.075", "--max-passes", "200",
                 "--image-width", "40", "--quiet"});
        const double cornell_aspect = camera_aspect(read_json(kCornellBox));
        const ImageData cornell = read_image(out2 / "render.png");
        CHECK(cornell.width == 40);
        CHECK(cornell.height == int(std::lround(40 / cornell_aspect)));
    }
}

TEST_CASE("bakes are deterministic and the seed changes the result", "[cli]") {
    TempDir dir;
    const json a = bake_ok(dir, kClosedRoom, dir / "a");
    const json b = bake_ok(dir, kClosedRoom, dir / "b");
    const std::vector<std::string> seed7 = concat(kFast, {"--seed", "7"});
    const json c = bake_ok(dir, kClosedRoom, dir / "c", seed7);

    const std::string bin_a = read_text(dir / "a" / "baked.bin");
    const std::string bin_b = read_text(dir / "b" / "baked.bin");
    const std::string bin_c = read_text(dir / "c" / "baked.bin");
    REQUIRE(!bin_a.empty());
    CHECK(bin_a == bin_b);
    CHECK(a.at("meshes") == b.at("meshes"));
    CHECK(a.at("energy") == b.at("energy"));
    CHECK(a.at("passes") == b.at("passes"));

    CHECK(c.at("settings").at("seed").get<std::uint64_t>() == 7u);
    CHECK(bin_c != bin_a);  // different hemicube rotations (and so maybe other elements refined)
}

TEST_CASE("bad input exits 2 with one line on stderr and no output directory", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "never";
    const json room = read_json(kClosedRoom);

    SECTION("missing scene file") {
        expect_bad_input(dir, bake_args(dir / "no_such_scene.gltf", out), out, "no_such_scene.gltf");
    }
    SECTION("truncated JSON") {
        const std::string text = read_text(kClosedRoom);
        const fs::path file = dir / "truncated.gltf";
        write_text(file, text.substr(0, text.size() / 2));
        expect_bad_input(dir, bake_args(file, out), out, "truncated.gltf");
    }
    SECTION("not JSON at all") {
        const fs::path file = dir / "garbage.gltf";
        write_text(file, "this is not a glTF file\n");
        expect_bad_input(dir, bake_args(file, out), out, "garbage.gltf");
    }
    SECTION("glTF 1.0") {
        json g = room;
        g["asset"]["version"] = "1.0";
        const fs::path file = dir / "old_version.gltf";
        write_json(file, g);
        expect_bad_input(dir, bake_args(file, out), out, "old_version.gltf");
    }
    SECTION("baseColorFactor above 1") {
        // One material only, emissive (so emission is not the problem), with red at 1.5.
        json g = room;
        json material = room["materials"][3];
        REQUIRE(material.contains("emissiveFactor"));
        material["pbrMetallicRoughness"]["baseColorFactor"] = {1.5, 0.5, 0.5, 1.0};
        g["materials"] = json::array({material});
        for (auto& mesh : g["meshes"])
            for (auto& prim : mesh["primitives"]) prim["material"] = 0;
        const fs::path file = dir / "too_bright.gltf";
        write_json(file, g);
        const RunResult r = expect_bad_input(dir, bake_args(file, out), out, "too_bright.gltf");
        CHECK(r.err.find("baseColorFactor") != std::string::npos);
    }
    SECTION("nothing emits") {
        json g = room;
        int zeroed = 0;
        for (auto& material : g["materials"]) {
            if (material.contains("emissiveFactor")) {
                material["emissiveFactor"] = {0.0, 0.0, 0.0};
                ++zeroed;
            }
        }
        REQUIRE(zeroed > 0);
        const fs::path file = dir / "dark.gltf";
        write_json(file, g);
        expect_bad_input(dir, bake_args(file, out), out, "dark.gltf");
    }
    SECTION("no triangles") {
        json g = room;
        g["scenes"][0]["nodes"] = json::array({8});  // only the camera node
        const fs::path file = dir / "empty.gltf";
        write_json(file, g);
        expect_bad_input(dir, bake_args(file, out), out, "empty.gltf");
    }
    SECTION("wrong file extension") {
        const fs::path file = dir / "scene.txt";
        write_text(file, read_text(kClosedRoom));
        expect_bad_input(dir, bake_args(file, out), out, "scene.txt");
    }
    SECTION("unknown camera") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--camera", "no_such_camera"})), out,
                         "no_such_camera");
    }
    SECTION("unknown option") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--no-such-flag"})), out,
                         "--no-such-flag");
    }
    SECTION("hemicube below the range") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--hemicube", "7"})), out, "--hemicube");
    }
    SECTION("odd hemicube") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--hemicube", "33"})), out, "--hemicube");
    }
    SECTION("an OpenCL device that does not exist") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--device", "opencl:9.9"})), out,
                         "opencl:9.9");
    }
    SECTION("a malformed device") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--device", "gpu"})), out, "--device gpu");
    }
    SECTION("verify with nothing to verify") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--device", "ref", "--verify"})), out,
                         "--verify");
    }
    SECTION("element size larger than the patch size") {
        expect_bad_input(dir,
                         bake_args(kClosedRoom, out,
                                   {"--hemicube", "32", "--patch-size", "0.5", "--element-size", "1.0", "--quiet"}),
                         out, "--element-size");
    }
    SECTION("negative patch size") {
        expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--patch-size", "-1"})), out,
                         "--patch-size");
    }
    SECTION("output path is an existing file") {
        const fs::path file = dir / "a_file";
        write_text(file, "keep me\n");
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, file));
        INFO("stderr: " << r.err);
        CHECK(r.code == 2);
        check_one_line(r.err);
        CHECK(r.err.find("a_file") != std::string::npos);
        CHECK(read_text(file) == "keep me\n");
    }
}

TEST_CASE("an existing output directory keeps the user's files", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "mine";
    fs::create_directories(out);
    const std::string notes = "my notes, not hemirad's\n";
    write_text(out / "notes.txt", notes);

    SECTION("a failed bake") {
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, out, concat(kFast, {"--camera", "no_such_camera"})));
        CHECK(r.code == 2);
        check_one_line(r.err);
        REQUIRE(fs::is_directory(out));
        CHECK(listing(out) == std::set<std::string>{"notes.txt"});
        CHECK(read_text(out / "notes.txt") == notes);
    }
    SECTION("a successful bake") {
        bake_ok(dir, kClosedRoom, out);
        CHECK(listing(out) ==
              std::set<std::string>{"notes.txt", "report.json", "baked.gltf", "baked.bin", "render.exr", "render.png"});
        CHECK(read_text(out / "notes.txt") == notes);
    }
}

TEST_CASE("previews are written every K passes", "[cli]") {
    TempDir dir;
    const std::vector<std::string> args = {"--hemicube", "32", "--patch-size", "1.0", "--element-size", "0.5",
                                           "--max-passes", "120", "--preview-every", "50", "--image-width", "32",
                                           "--quiet"};
    // One shooter a step: a preview at exactly every 50th pass.
    const fs::path out = dir / "out";
    const json report = bake_ok(dir, kClosedRoom, out, concat(args, {"--batch", "1"}));
    REQUIRE(report.at("passes").get<long>() == 120);  // closed_room does not converge in 120 passes
    CHECK(report.at("steps").at("count") == 120);
    CHECK(report.at("steps").at("largest") == 1);
    REQUIRE(fs::is_directory(out / "preview"));
    CHECK(listing(out / "preview") == std::set<std::string>{"pass_000050.png", "pass_000100.png"});
    CHECK(listing(out) ==
          std::set<std::string>{"preview", "report.json", "baked.gltf", "baked.bin", "render.exr", "render.png"});
    const ImageData preview = read_image(out / "preview" / "pass_000100.png");
    CHECK(preview.width == 32);
    CHECK(preview.height == 24);

    // By default a step may take several shooters: a preview after the step that crosses each
    // multiple of 50, named by that step's last pass, and the bake's numbers as without previews.
    const fs::path shared = dir / "shared", plain = dir / "plain";
    const json s = bake_ok(dir, kClosedRoom, shared, args);
    REQUIRE(s.at("steps").at("largest").get<long>() > 1);
    const std::set<std::string> names = listing(shared / "preview");
    REQUIRE(names.size() == 2);
    long k = 50;
    for (const std::string& name : names) {
        CAPTURE(name);
        REQUIRE(name.size() == std::string("pass_000000.png").size());
        const long pass = std::stol(name.substr(5, 6));
        CHECK(pass >= k);
        CHECK(pass < k + s.at("steps").at("largest").get<long>());
        k += 50;
    }
    std::vector<std::string> without = args;
    const auto flag = std::find(without.begin(), without.end(), "--preview-every");
    REQUIRE(flag != without.end());
    without.erase(flag, flag + 2);
    bake_ok(dir, kClosedRoom, plain, concat(without, {"--solver", "progressive"}));  // auto: progressive with previews
    CHECK(read_text(plain / "baked.bin") == read_text(shared / "baked.bin"));
}

TEST_CASE("devices and help and a missing subcommand", "[cli]") {
    TempDir dir;
    SECTION("devices --json") {
        const RunResult r = run_hemirad(dir, {"devices", "--json"});
        CHECK(r.code == 0);
        const json devices = json::parse(r.out);
        REQUIRE(devices.is_array());
        REQUIRE(!devices.empty());
        bool has_ref = false;
        for (const auto& d : devices) {
            REQUIRE(d.contains("backend"));
            CHECK(d.at("backend").is_string());
            has_ref = has_ref || d.at("backend") == "ref";
        }
        CHECK(has_ref);
    }
    SECTION("devices") {
        const RunResult r = run_hemirad(dir, {"devices"});
        CHECK(r.code == 0);
        CHECK(r.out.find("ref") != std::string::npos);
    }
    SECTION("--help") {
        const RunResult r = run_hemirad(dir, {"--help"});
        CHECK(r.code == 0);
        CHECK(r.out.find("bake") != std::string::npos);
        CHECK(r.out.find("devices") != std::string::npos);
    }
    SECTION("bake --help") {
        const RunResult r = run_hemirad(dir, {"bake", "--help"});
        CHECK(r.code == 0);
        for (const char* option : {"--hemicube", "--patch-size", "--element-size", "--threshold", "--max-passes",
                                   "--seed", "--device", "--camera", "--preview-every", "--quiet", "--verify"}) {
            INFO("option " << option);
            CHECK(r.out.find(option) != std::string::npos);
        }
    }
    SECTION("no subcommand") {
        const RunResult r = run_hemirad(dir, {});
        CHECK(r.code == 2);
        check_one_line(r.err);
        CHECK(listing(dir.path()).empty());
    }
    SECTION("bake without a scene") {
        const RunResult r = run_hemirad(dir, {"bake"});
        CHECK(r.code == 2);
        check_one_line(r.err);
        CHECK(!fs::exists(dir / "out"));
    }
}

TEST_CASE("the default output directory is out/", "[cli]") {
    TempDir dir;
    const RunResult r = run_hemirad(dir, concat({"bake", kClosedRoom.string()}, kFast));
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    CHECK(fs::is_regular_file(dir / "out" / "report.json"));
    CHECK(fs::is_regular_file(dir / "out" / "baked.gltf"));
}

TEST_CASE("mesh names fall back to the mesh name then node index", "[cli]") {
    TempDir dir;
    json g = read_json(kClosedRoom);
    // cube node: no name, so its mesh's name; ceiling node: no name and a nameless mesh.
    std::size_t cube = 0, ceiling = 0;
    for (std::size_t i = 0; i < g["nodes"].size(); ++i) {
        if (g["nodes"][i].value("name", "") == "cube") cube = i;
        if (g["nodes"][i].value("name", "") == "ceiling") ceiling = i;
    }
    REQUIRE(cube != ceiling);
    g["nodes"][cube].erase("name");
    g["meshes"][g["nodes"][cube]["mesh"].get<std::size_t>()]["name"] = "box_mesh";
    g["nodes"][ceiling].erase("name");
    g["meshes"][g["nodes"][ceiling]["mesh"].get<std::size_t>()].erase("name");
    const fs::path file = dir / "renamed.gltf";
    write_json(file, g);

    const std::vector<std::string> expected = expected_mesh_names(g);
    CHECK(std::count(expected.begin(), expected.end(), "box_mesh") == 1);
    CHECK(std::count(expected.begin(), expected.end(), "node" + std::to_string(ceiling)) == 1);

    const json report = bake_ok(dir, file, dir / "out");
    CHECK(sorted(report_mesh_names(report)) == sorted(expected));
}

TEST_CASE("results are scale invariant end to end", "[cli]") {
    TempDir dir;
    const json room = read_json(kClosedRoom);
    // Default patch and element sizes: relative to the scene's size, so each bake meshes alike.
    // Scaling by 1e-3 or 1e3 rounds every vertex, which flips near-ties in the choice of the
    // next shooter; a different shooting order draws different hemicube rotations, i.e. acts
    // like another seed. At N = 32 that noise alone is ~0.7% per mesh (about what --seed 2
    // changes), at N = 128 ~0.25%, so N = 128 keeps the 0.5% check meaningful; it costs
    // about 1 s per bake.
    const std::vector<std::string> args = {"--hemicube", "128", "--max-passes", "300", "--image-width", "32", "--quiet"};
    const json base = bake_ok(dir, kClosedRoom, dir / "base", args);

    std::map<std::string, json> base_meshes;
    for (const auto& m : base.at("meshes")) base_meshes[m.at("name").get<std::string>()] = m;
    REQUIRE(base_meshes.size() == 8);

    for (const double s : {1e-3, 1e3}) {
        INFO("scale " << s);
        const fs::path file = dir / (s < 1.0 ? "room_milli.gltf" : "room_kilo.gltf");
        write_json(file, scaled_scene(room, s));
        const json scaled = bake_ok(dir, file, dir / (s < 1.0 ? "milli" : "kilo"), args);

        CHECK(scaled.at("counts") == base.at("counts"));
        CHECK(scaled.at("settings").at("patch_size").get<double>() ==
              Approx(base.at("settings").at("patch_size").get<double>() * s).epsilon(1e-9));
        REQUIRE(scaled.at("meshes").size() == base.at("meshes").size());
        for (const auto& m : scaled.at("meshes")) {
            const std::string name = m.at("name").get<std::string>();
            INFO("mesh " << name);
            REQUIRE(base_meshes.count(name) == 1);
            const json& b = base_meshes[name];
            CHECK(m.at("area").get<double>() == Approx(b.at("area").get<double>() * s * s).epsilon(1e-9));
            for (int c = 0; c < 3; ++c) {
                const double x = m.at("radiosity")[c].get<double>();
                const double y = b.at("radiosity")[c].get<double>();
                INFO("channel " << c << ": " << x << " vs unscaled " << y);
                CHECK(std::abs(x - y) <= 5e-3 * std::abs(y) + 1e-9);
            }
        }
    }
}

namespace {

// Starts a long bake with a preview every pass, waits until the second preview is on disk (so
// the solver loop is running and files exist), sends `signal` (INT, TERM, HUP; stdout says
// "signal-sent" if the process was still there to get it), and returns hemirad's exit code.
// `env --default-signal` undoes what the shell does to a background job (SIGINT ignored, which
// hemirad respects, as it respects nohup's SIGHUP); `ignore` names a signal the bake starts with
// ignored, and `max_passes` > 0 lets the bake end by itself.
RunResult interrupted_bake(const TempDir& dir, const std::string& out, const std::string& signal = "INT",
                           const std::string& ignore = "", int max_passes = 0) {
    // The first preview says the solve is under way (a step may shoot several passes: its name
    // is the step's last).
    const std::string previews = out + "/preview";
    std::string script = (ignore.empty() ? "" : "trap '' " + ignore + "; ") + "env --default-signal=INT" +
                         (ignore.empty() ? ",HUP " : " ") + shell_quote(HEMIRAD_EXE);
    for (const std::string& a : {std::string("bake"), kClosedRoom.string(), std::string("-o"), out,
                                 std::string("--hemicube"), std::string("256"), std::string("--threshold"),
                                 std::string("1e-7"), std::string("--preview-every"), std::string("1"),
                                 std::string("--image-width"), std::string("32"), std::string("--quiet")})
        script += " " + shell_quote(a);
    if (max_passes > 0) script += " --max-passes " + std::to_string(max_passes);
    script += " & pid=$!; i=0; while [ -z \"$(ls " + shell_quote(previews) +
              " 2>/dev/null)\" ] && [ $i -lt 400 ]; do sleep 0.05; i=$((i+1)); done; kill -" + signal + " $pid && echo signal-sent; wait $pid";
    return run_shell(dir, script);
}

}  // namespace

TEST_CASE("an interrupted bake leaves no output behind", "[cli]") {
    TempDir dir;
    fs::create_directories(dir / "mine");
    write_text(dir / "mine" / "notes.txt", "keep\n");

    SECTION("a new output directory") {
        const RunResult r = interrupted_bake(dir, "out");
        INFO("stderr: " << r.err);
        CHECK(r.code != 0);
        CHECK(r.code != 2);  // not bad input
        CHECK(r.err.find("interrupted") != std::string::npos);
        CHECK(!fs::exists(dir / "out"));
    }
    SECTION("an existing output directory") {
        const RunResult r = interrupted_bake(dir, "mine");
        INFO("stderr: " << r.err);
        CHECK(r.code != 0);
        REQUIRE(fs::is_directory(dir / "mine"));
        CHECK(listing(dir / "mine") == std::set<std::string>{"notes.txt"});
        CHECK(read_text(dir / "mine" / "notes.txt") == "keep\n");
    }
}

// Known bug (reported, not fixed here): OutputTransaction creates missing parent directories
// with create_directories but on failure removes only the last one, so a/b stays behind.
TEST_CASE("an interrupted bake into a new nested directory removes every directory it made", "[cli]") {
    TempDir dir;
    const RunResult r = interrupted_bake(dir, "a/b/out");
    INFO("stderr: " << r.err);
    CHECK(r.code != 0);
    CHECK(!fs::exists(dir / "a" / "b" / "out"));
    CHECK(!fs::exists(dir / "a"));
}

// Known bug (reported, not fixed here): scene warnings are printed before the checks that
// follow loading (--camera, --element-size), so a bad-input run prints more than one line.
TEST_CASE("bad input after a scene warning is still one line on stderr", "[cli]") {
    TempDir dir;
    json g = read_json(kClosedRoom);
    g["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = {1.0, 1.0, 1.0, 1.0};  // clamped, warned
    const fs::path file = dir / "white_walls.gltf";
    write_json(file, g);
    const fs::path out = dir / "never";
    expect_bad_input(dir, bake_args(file, out, concat(kFast, {"--camera", "no_such_camera"})), out,
                     "no_such_camera");
}

// Every backend a bake can run on (--device ref, each opencl:P.D, the reference with a device
// sharing its batches) bakes the closed room byte for byte as the reference; one OpenCL device
// does so under --verify too, every shot checked and no cell off.
TEST_CASE("bakes on every --device give the reference bake byte for byte", "[cli][backends]") {
    const hemirad::test::Backend& b = hemirad::test::backend(GENERATE(from_range(hemirad::test::backend_names())));
    HEMIRAD_SKIP_ABSENT(hemirad::test::bakeable(b));
    INFO("backend " << b.name << ", --device " << b.device);
    const bool one_device = b.device.rfind("opencl:", 0) == 0;
    const TempDir dir;
    const fs::path on_backend = dir / "backend", with_ref = dir / "ref";
    // A list's planned batch is one per member's share; --batch 1 as one device plans it.
    const std::vector<std::string> args = concat(kFast, {"--batch", "1"});
    const json report = bake_ok(dir, kClosedRoom, on_backend,
                                concat(args, one_device ? std::vector<std::string>{"--device", b.device, "--verify"}
                                                        : std::vector<std::string>{"--device", b.device}));
    const json ref_report = bake_ok(dir, kClosedRoom, with_ref, concat(args, {"--device", "ref"}));
    CHECK(report["device"]["id"] == b.device);
    CHECK(report["settings"]["batch"] == 1);
    CHECK(report["passes"] == ref_report["passes"]);
    if (one_device) {
        CHECK(report["device"]["backend"] == "opencl");
        CHECK(report["verify"]["shots_checked"].get<long>() == report["passes"].get<long>());
        CHECK(report["verify"]["cells_mismatched"].get<long>() == 0);
    }
    CHECK(read_text(on_backend / "baked.bin") == read_text(with_ref / "baked.bin"));
}

TEST_CASE("batched bakes on every --device give the batched reference bake byte for byte", "[cli][backends]") {
    const hemirad::test::Backend& b = hemirad::test::backend(GENERATE(from_range(hemirad::test::backend_names())));
    HEMIRAD_SKIP_ABSENT(hemirad::test::bakeable(b));
    INFO("backend " << b.name << ", --device " << b.device);
    const bool one_device = b.device.rfind("opencl:", 0) == 0;
    const TempDir dir;
    const fs::path on_backend = dir / "backend", with_ref = dir / "ref";
    const std::vector<std::string> args = concat(kFast, {"--batch", "6"});
    const json report = bake_ok(dir, kClosedRoom, on_backend,
                                concat(args, one_device ? std::vector<std::string>{"--device", b.device, "--verify"}
                                                        : std::vector<std::string>{"--device", b.device}));
    const json ref_report = bake_ok(dir, kClosedRoom, with_ref, concat(args, {"--device", "ref"}));
    CHECK(report["device"]["id"] == b.device);
    CHECK(report["settings"]["batch"] == 6);
    CHECK(report["passes"] == ref_report["passes"]);
    if (one_device) {
        // Every shot the engine made; a batch cut short by convergence shoots more than it applies.
        CHECK(report["verify"]["shots_checked"].get<long>() >= report["passes"].get<long>());
        CHECK(report["verify"]["cells_mismatched"].get<long>() == 0);
    }
    CHECK(read_text(on_backend / "baked.bin") == read_text(with_ref / "baked.bin"));
}

TEST_CASE("HEMIRAD_DEVICE picks the device when --device is auto", "[cli]") {
    const TempDir dir;
    const fs::path out = dir / "out";
    const RunResult bad = run_hemirad(dir, bake_args(kClosedRoom, out), "HEMIRAD_DEVICE=bogus ");
    INFO("stderr: [" << bad.err << "]");
    CHECK(bad.code == 2);
    check_one_line(bad.err);
    CHECK(bad.err.find("HEMIRAD_DEVICE") != std::string::npos);
    CHECK(!fs::exists(out));

    const RunResult good = run_hemirad(dir, bake_args(kClosedRoom, out), "HEMIRAD_DEVICE=ref ");
    REQUIRE(good.code == 0);
    CHECK(read_json(out / "report.json")["device"]["backend"] == "ref");
}

TEST_CASE("auto falls back to the reference when the OpenCL kernels do not build", "[cli]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const TempDir dir;
    const fs::path out = dir / "out", forced = dir / "forced";
    const std::string broken = "HEMIRAD_OPENCL_OPTIONS=-DClipPolygon=42 ";  // turns a kernel typedef into nonsense
    const RunResult fell_back = run_hemirad(dir, bake_args(kClosedRoom, out), broken);
    INFO("stderr: [" << fell_back.err << "]");
    REQUIRE(fell_back.code == 0);
    CHECK(fell_back.err.find("using the reference engine") != std::string::npos);
    const json report = read_json(out / "report.json");
    CHECK(report["device"]["backend"] == "ref");
    CHECK(report["warnings"].dump().find("using the reference engine") != std::string::npos);

    // Asked for by name, the same failure is an error with the build log, and nothing is written.
    const RunResult failed = run_hemirad(dir, bake_args(kClosedRoom, forced, concat(kFast, {"--device", "opencl"})), broken);
    CHECK(failed.code == 1);
    CHECK(failed.err.find("build failed") != std::string::npos);
    CHECK(!fs::exists(forced));
}

TEST_CASE("zero-area triangles are dropped and counted in the report with a warning", "[cli]") {
    // closed_room plus a node of three degenerate triangles (collinear, a repeated vertex, a
    // point) in a buffer of their own: the bake drops exactly those, says so, and the numbers of
    // every other node are the plain room's.
    const TempDir dir;
    json scene = read_json(kClosedRoom);
    const float p[27] = {0, 1, 0, 1, 1, 0, 2, 1, 0,  // collinear
                         0, 1, 1, 0, 1, 1, 1, 1, 1,  // a repeated vertex
                         1, 2, 1, 1, 2, 1, 1, 2, 1}; // a point
    write_text(dir / "degenerate.bin", std::string(reinterpret_cast<const char*>(p), sizeof p));
    const std::size_t buffer = scene["buffers"].size(), view = scene["bufferViews"].size(),
                      accessor = scene["accessors"].size(), mesh = scene["meshes"].size(), node = scene["nodes"].size();
    scene["buffers"].push_back({{"uri", "degenerate.bin"}, {"byteLength", sizeof p}});
    scene["bufferViews"].push_back({{"buffer", buffer}, {"byteLength", sizeof p}});
    scene["accessors"].push_back({{"bufferView", view}, {"componentType", 5126}, {"count", 9}, {"type", "VEC3"},
                                  {"min", {0, 1, 0}}, {"max", {2, 2, 1}}});
    scene["meshes"].push_back({{"name", "slivers"}, {"primitives", {{{"attributes", {{"POSITION", accessor}}}, {"material", 0}}}}});
    scene["nodes"].push_back({{"name", "slivers"}, {"mesh", mesh}});
    scene["scenes"][0]["nodes"].push_back(node);
    write_json(dir / "with_slivers.gltf", scene);

    const json plain = bake_ok(dir, kClosedRoom, dir / "plain");
    const RunResult r = run_hemirad(dir, bake_args(dir / "with_slivers.gltf", dir / "out"));
    INFO("stderr: [" << r.err << "]");
    REQUIRE(r.code == 0);
    CHECK(r.err.find("3 zero-area triangles dropped (of ") != std::string::npos);
    CHECK(read_text(dir / "out" / "report.json").find("null") == std::string::npos);  // no 0 / 0 in any average
    const json report = read_json(dir / "out" / "report.json");
    CHECK(report["counts"]["dropped_triangles"] == 3);
    CHECK(report["counts"]["triangles"] == plain["counts"]["triangles"].get<int>() + 3);
    CHECK(report["counts"]["elements"] == plain["counts"]["elements"]);
    CHECK(report["warnings"].dump().find("zero-area triangles dropped") != std::string::npos);
    const json& meshes = report["meshes"];
    REQUIRE(meshes.size() == plain["meshes"].size() + 1);
    for (std::size_t i = 0; i < plain["meshes"].size(); ++i) CHECK(meshes[i] == plain["meshes"][i]);
    CHECK(meshes.back()["name"] == "slivers");
    CHECK(meshes.back()["area"] == 0.0);
    CHECK(meshes.back()["radiosity"] == json::array({0.0, 0.0, 0.0}));
}

// Faults (issue 6): HEMIRAD_FAULT makes the OpenCL engine fail as a broken device would. A bake on
// the automatic choice starts again on the reference and ends with exactly the reference bake's
// numbers; a device asked for by name stops the bake (exit 1) with the reason, writing nothing.
TEST_CASE("a device that fails part-way: auto starts again on the reference and a named device stops", "[cli][faults]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const TempDir dir;
    const std::vector<std::string> args = concat(kFast, {"--solver", "progressive", "--batch", "4"});
    const fs::path ref = dir / "ref", fell_back = dir / "fell_back", named = dir / "named";
    bake_ok(dir, kClosedRoom, ref, concat(args, {"--device", "ref"}));

    const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, fell_back, args), "HEMIRAD_FAULT=fail-after:2 ");
    INFO("stderr: [" << r.err << "]");
    REQUIRE(r.code == 0);
    CHECK(r.err.find("failed part-way") != std::string::npos);
    const json report = read_json(fell_back / "report.json");
    CHECK(report["device"]["backend"] == "ref");
    CHECK(report["device"]["fallback"]["from"].get<std::string>().rfind("opencl:", 0) == 0);
    CHECK(report["device"]["fallback"]["why"].get<std::string>().find("CL_INVALID_COMMAND_QUEUE") != std::string::npos);
    CHECK(report["warnings"].dump().find("starting again on the reference engine") != std::string::npos);
    CHECK(read_text(fell_back / "baked.bin") == read_text(ref / "baked.bin"));

    const RunResult stopped =
        run_hemirad(dir, bake_args(kClosedRoom, named, concat(args, {"--device", "opencl"})), "HEMIRAD_FAULT=fail-after:2 ");
    INFO("stderr: [" << stopped.err << "]");
    CHECK(stopped.code == 1);
    CHECK(stopped.err.find("hemirad: device failed: ") != std::string::npos);
    CHECK(stopped.err.find("CL_INVALID_COMMAND_QUEUE") != std::string::npos);
    CHECK(!fs::exists(named));
}

TEST_CASE("a device that returns wrong numbers: --verify catches it and auto starts again on the reference", "[cli][faults]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const TempDir dir;
    const std::vector<std::string> args = concat(kFast, {"--solver", "progressive"});
    const fs::path ref = dir / "ref";
    bake_ok(dir, kClosedRoom, ref, concat(args, {"--device", "ref"}));

    // Wrong from the first shot: the automatic choice's probe shot sees it before the bake starts.
    const fs::path probed = dir / "probed";
    const RunResult p = run_hemirad(dir, bake_args(kClosedRoom, probed, args), "HEMIRAD_FAULT=wrong-after:0 ");
    INFO("stderr: [" << p.err << "]");
    REQUIRE(p.code == 0);
    CHECK(p.err.find("disagrees with the reference") != std::string::npos);
    CHECK(read_json(probed / "report.json")["device"]["backend"] == "ref");
    CHECK(read_text(probed / "baked.bin") == read_text(ref / "baked.bin"));

    // Wrong after the probe: --verify catches it part-way.
    const fs::path verified = dir / "verified";
    const RunResult v = run_hemirad(dir, bake_args(kClosedRoom, verified, concat(args, {"--verify"})),
                                    "HEMIRAD_FAULT=wrong-after:1 ");
    INFO("stderr: [" << v.err << "]");
    REQUIRE(v.code == 0);
    const json report = read_json(verified / "report.json");
    CHECK(report["device"]["backend"] == "ref");
    CHECK(report["device"]["fallback"]["why"].get<std::string>().rfind("verification failed: ", 0) == 0);
    CHECK(!report.contains("verify"));  // the reference engine is not checked against itself
    CHECK(read_text(verified / "baked.bin") == read_text(ref / "baked.bin"));

    // Asked for by name, the mismatch stops the bake with the numbers.
    const fs::path named = dir / "named";
    const RunResult n = run_hemirad(dir, bake_args(kClosedRoom, named, concat(args, {"--verify", "--device", "opencl"})),
                                    "HEMIRAD_FAULT=wrong-after:1 ");
    INFO("stderr: [" << n.err << "]");
    CHECK(n.code == 1);
    CHECK(n.err.find("hemirad: verification failed: ") != std::string::npos);
    CHECK(n.err.find("the reference says") != std::string::npos);
    CHECK(!fs::exists(named));
}

TEST_CASE("a device out of memory: batches shrink and the numbers do not change", "[cli][faults]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const TempDir dir;
    const std::vector<std::string> args = concat(kFast, {"--solver", "progressive", "--batch", "8"});
    const fs::path ref = dir / "ref", shrunk = dir / "shrunk", none = dir / "none";
    bake_ok(dir, kClosedRoom, ref, concat(args, {"--device", "ref"}));

    const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, shrunk, concat(args, {"--device", "opencl"})),
                                    "HEMIRAD_FAULT=oom-above:3 ");
    INFO("stderr: [" << r.err << "]");
    REQUIRE(r.code == 0);
    const json report = read_json(shrunk / "report.json");
    CHECK(report["device"]["backend"] == "opencl");
    CHECK(report["warnings"].dump().find("ran out of memory") != std::string::npos);
    CHECK(report["warnings"].dump().find("as few as 2 shots") != std::string::npos);  // 8 → 4 → 2
    CHECK(read_text(shrunk / "baked.bin") == read_text(ref / "baked.bin"));

    // Not even one shot fits: a named device stops; auto uses the reference from the start.
    const RunResult n = run_hemirad(dir, bake_args(kClosedRoom, none, concat(args, {"--device", "opencl"})),
                                    "HEMIRAD_FAULT=oom-above:0 ");
    INFO("stderr: [" << n.err << "]");
    CHECK(n.code == 1);
    CHECK(n.err.find("cannot hold the mesh") != std::string::npos);
    CHECK(!fs::exists(none));
    const RunResult a = run_hemirad(dir, bake_args(kClosedRoom, none, args), "HEMIRAD_FAULT=oom-above:0 ");
    INFO("stderr: [" << a.err << "]");
    REQUIRE(a.code == 0);
    CHECK(read_json(none / "report.json")["device"]["backend"] == "ref");
    CHECK(read_text(none / "baked.bin") == read_text(ref / "baked.bin"));

    // A malformed HEMIRAD_FAULT is bad usage, never silently no fault.
    const RunResult bad = run_hemirad(dir, bake_args(kClosedRoom, dir / "bad", args), "HEMIRAD_FAULT=oom-above ");
    CHECK(bad.code == 2);
    check_one_line(bad.err);
    CHECK(bad.err.find("HEMIRAD_FAULT=oom-above") != std::string::npos);
}

TEST_CASE("no OpenCL platform at all: auto bakes on the reference and opencl or --verify is bad usage", "[cli][faults]") {
    const TempDir dir;
    fs::create_directories(dir / "no_icds");
    const std::string no_platform = "OCL_ICD_VENDORS=" + shell_quote((dir / "no_icds").string()) + " ";
    const fs::path out = dir / "out";
    const RunResult a = run_hemirad(dir, bake_args(kClosedRoom, out), no_platform);
    INFO("stderr: [" << a.err << "]");
    REQUIRE(a.code == 0);
    CHECK(read_json(out / "report.json")["device"]["backend"] == "ref");
    for (const std::vector<std::string>& extra : {std::vector<std::string>{"--device", "opencl"},
                                                  std::vector<std::string>{"--device", "opencl:0.0"},
                                                  std::vector<std::string>{"--verify"}}) {
        const fs::path none = dir / "none";
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, none, concat(kFast, extra)), no_platform);
        CAPTURE(extra);
        CHECK(r.code == 2);
        check_one_line(r.err);
        CHECK(r.err.find("OpenCL device") != std::string::npos);
        CHECK(!fs::exists(none));
    }
    const RunResult d = run_hemirad(dir, {"devices"}, no_platform);
    CHECK(d.code == 0);
    CHECK(d.out.find("no OpenCL platform or device found") != std::string::npos);
}

namespace {

// `hemirad bench` on a tiny closed procedural scene and a file, quickly (no calibration).
std::vector<std::string> bench_args(const std::vector<std::string>& extra) {
    return concat({"bench", "procedural:100", kClosedRoom.string(), "--hemicube", "16,32", "--shots", "2",
                   "--repeats", "2", "--no-calibrate"},
                  extra);
}

#if HEMIRAD_HAVE_EMBREE
constexpr std::size_t kPeers = 1;  // the Embree ray caster
#else
constexpr std::size_t kPeers = 0;
#endif

}  // namespace

TEST_CASE("bench times every engine on every scene and N and writes the JSON", "[cli][bench]") {
    const TempDir dir;
    const fs::path file = dir / "results.json";
    const RunResult r = run_hemirad(dir, bench_args({"--json", file.string()}));
    INFO("stderr: [" << r.err << "]");
    REQUIRE(r.code == 0);
    const json doc = read_json(file);
    const std::size_t engines = 1 + kPeers + hemirad::ocl::list_devices().size();
    REQUIRE(doc["results"].size() == 2 * 2 * engines);  // scenes × N × engines
    CHECK(all_numbers_finite(doc));
    // closed_room's triangles, from the file itself: one indexed triangle list per primitive.
    const json room = read_json(kClosedRoom);
    std::size_t room_triangles = 0;
    for (const auto& mesh : room["meshes"])
        for (const auto& prim : mesh["primitives"])
            room_triangles += room["accessors"][prim["indices"].get<int>()]["count"].get<std::size_t>() / 3;
    std::set<std::string> seen;
    for (const auto& row : doc["results"]) {
        INFO(row.dump());
        for (const char* key : {"engine", "device", "scene", "triangles", "hemicube", "shots_per_s"})
            CHECK(row.contains(key));
        seen.insert(row["engine"].get<std::string>());
        const double n = row["hemicube"].get<double>(), shots_per_s = row["shots_per_s"].get<double>();
        CHECK(shots_per_s > 0.0);
        CHECK(row["samples_per_s"].get<double>() == Approx(3.0 * n * n * shots_per_s));
        CHECK(row["ms_per_shot"]["min"].get<double>() <= row["ms_per_shot"]["median"].get<double>());
        CHECK(row["vs_ref"]["worst_l1_dF"].get<double>() <= 1e-3);
        const double sum_max = row["sum_F_blocked"]["max"].get<double>();
        CHECK(sum_max <= 1.0 + 1e-9);
        if (row["scene"] == "procedural:100") {
            // Closed: every direction from every patch hits a surface, so each shot sums to 1.
            CHECK(row["closed"] == true);
            CHECK(row["sum_F_blocked"]["min"].get<double>() >= 1.0 - 1e-9);
        } else {
            CHECK(row["scene"] == kClosedRoom.string());
            CHECK(row["triangles"] == room_triangles);
        }
    }
    CHECK(seen.count("ref") == 1);
    if (!hemirad::ocl::list_devices().empty()) CHECK(seen.count("opencl") == 1);
    // A table row per engine, scene and N on stdout.
    CHECK(std::count(r.out.begin(), r.out.end(), '\n') > static_cast<long>(doc["results"].size()));
}

TEST_CASE("bench rejects bad input with exit 2 before any output and keeps an existing JSON file", "[cli][bench]") {
    const TempDir dir;
    const fs::path file = dir / "results.json";
    write_text(file, "earlier results\n");
    const auto bad = [&](std::vector<std::string> args, const std::string& token) {
        const RunResult r = run_hemirad(dir, args);
        INFO("stderr: [" << r.err << "]");
        CHECK(r.code == 2);
        check_one_line(r.err);
        CHECK(r.err.find(token) != std::string::npos);
        CHECK(r.out.empty());
        CHECK(read_text(file) == "earlier results\n");
        CHECK(listing(dir.path()) == std::set<std::string>{"results.json"});
    };
    const std::string json_file = file.string();
    bad({"bench", "no_such_scene.gltf", "--json", json_file}, "no_such_scene.gltf");
    bad({"bench", "procedural:abc", "--json", json_file}, "procedural:abc");
    bad({"bench", "procedural:100", "--hemicube", "33", "--json", json_file}, "33");
    bad({"bench", "procedural:100", "--engines", "nonsense", "--json", json_file}, "nonsense");
    bad({"bench", "--json", json_file}, "no scene");
    bad({"bench", "procedural:100", "--json", (dir / "missing" / "r.json").string()}, "missing");
}

TEST_CASE("bench refuses a fast wrong OpenCL kernel: no result, no JSON", "[cli][bench]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const TempDir dir;
    const fs::path file = dir / "results.json";
    // HEMIRAD_FAULT=wrong-after:0: every launch returns a wrong form factor, as a broken kernel or
    // device might. (A kernel built for the other setup layout than the host drives did this
    // before HEMIRAD_OPENCL_OPTIONS set the host's knobs too.)
    const std::string wrong = "HEMIRAD_FAULT=wrong-after:0 ";
    const RunResult r = run_hemirad(dir, {"bench", "procedural:100", "--hemicube", "16", "--shots", "2", "--repeats",
                                          "1", "--no-calibrate", "--engines", "ref,opencl", "--patch-size", "1",
                                          "--element-size", "1", "--json", file.string()},
                                    wrong);
    INFO("stderr: [" << r.err << "]");
    CHECK(r.code == 1);  // (the device compiler may add its own warnings to stderr)
    CHECK(r.err.find("hemirad: verification failed: opencl on procedural:100") != std::string::npos);
    CHECK(r.err.find("disagrees with the reference") != std::string::npos);
    CHECK(!fs::exists(file));
}

TEST_CASE("quality presets fill in the settings the options leave out, options override them", "[cli][quality]") {
    const TempDir dir;
    // closed_room spans x ∈ [−2, 2], y ∈ [0, 2.5], z ∈ [−2.5, 2.5] (scenes/README.md).
    const double diagonal = std::sqrt(4.0 * 4.0 + 2.5 * 2.5 + 5.0 * 5.0);
    const std::vector<std::string> quick = {"--max-passes", "20", "--image-width", "32", "--quiet"};
    for (const hemirad::QualityPreset& preset : hemirad::kQualityPresets) {
        INFO(preset.name);
        const fs::path out = dir / preset.name;
        const json report = bake_ok(dir, kClosedRoom, out, concat({"--quality", preset.name}, quick));
        const json& s = report["settings"];
        CHECK(s["quality"] == preset.name);
        CHECK(s["hemicube"] == preset.hemicube);
        CHECK(s["threshold"].get<double>() == preset.threshold);
        CHECK(s["patch_size"].get<double>() == Approx(diagonal * preset.patch_fraction).epsilon(1e-9));
        CHECK(s["element_size"].get<double>() ==
              Approx(diagonal * preset.patch_fraction / preset.elements_per_patch_edge).epsilon(1e-9));
        CHECK(s["contrast"].get<double>() == preset.contrast);
        CHECK(s["gather"] == preset.gather);
        CHECK(s["gather_passes"] == preset.gather_passes);
        CHECK(s["cluster_apart"] == true);  // clusters join across gaps unless --no-cluster-apart
    }
    const json overridden =
        bake_ok(dir, kClosedRoom, dir / "overridden",
                concat({"--quality", "high", "--hemicube", "32", "--threshold", "0.5", "--patch-size", "1.5",
                        "--gather", "0", "--contrast", "0.3", "--no-cluster-apart"},
                       quick));
    CHECK(overridden["settings"]["hemicube"] == 32);
    CHECK(overridden["settings"]["gather"] == 0);
    CHECK(overridden["settings"]["gather_passes"] == hemirad::quality_preset("high").gather_passes);
    CHECK(overridden["settings"]["contrast"].get<double>() == 0.3);
    CHECK(overridden["settings"]["cluster_apart"] == false);
    CHECK(overridden["counts"]["gather_points"] == 0);
    CHECK(overridden["settings"]["threshold"].get<double>() == 0.5);
    CHECK(overridden["settings"]["patch_size"].get<double>() == 1.5);
    CHECK(overridden["settings"]["element_size"].get<double>() ==
          Approx(1.5 / hemirad::quality_preset("high").elements_per_patch_edge));
    expect_bad_input(dir, bake_args(kClosedRoom, dir / "never", {"--quality", "best"}), dir / "never", "quality");
}

TEST_CASE("bench --accuracy --quick: analytic errors, room runs, the front, the Cornell box's pixels", "[cli][bench]") {
    const TempDir dir;
    const fs::path file = dir / "accuracy.json";
    // From the repository root, where the scene and its path-traced reference are.
    const RunResult r = run_shell(dir, "cd " + shell_quote(kSourceDir.string()) + " && " + shell_quote(HEMIRAD_EXE) +
                                           " bench --accuracy --quick --json " + shell_quote(file.string()));
    INFO("stderr: [" << r.err << "]");
    REQUIRE(r.code == 0);
    const json doc = read_json(file);
    CHECK(all_numbers_finite(doc));
    const json& acc = doc["accuracy"];
    REQUIRE(!acc["analytic"].empty());
    for (const auto& row : acc["analytic"]) {
        INFO(row.dump());
        // REFERENCES.md's values; shooters of a quarter of the square are within a few percent.
        CHECK(row["exact"].get<double>() == (row["case"].get<std::string>().rfind("parallel", 0) == 0
                                                 ? 0.1998248957
                                                 : 0.2000437761));
        const double error = std::abs(row["value"].get<double>() / row["exact"].get<double>() - 1.0);
        CHECK(row["rel_error"].get<double>() == Approx(error));
        if (row["patch_size"].get<double>() <= 0.25) CHECK(row["rel_error"].get<double>() < 0.03);
    }
    const json& runs = acc["room"]["runs"];
    REQUIRE(runs.size() >= 3);
    for (const auto& run : runs) {
        INFO(run.dump());
        CHECK(run["rms_rel_error"].get<double>() < 0.15);
        CHECK(run["max_surface_error"].get<double>() < 0.05);
        CHECK(run["seconds"].get<double>() > 0.0);
    }
    // The front: fastest first, each run more accurate than the one before.
    const json& front = acc["room"]["pareto"];
    REQUIRE(!front.empty());
    for (std::size_t i = 1; i < front.size(); ++i) {
        const json &a = runs[front[i - 1].get<std::size_t>()], &b = runs[front[i].get<std::size_t>()];
        CHECK(a["seconds"].get<double>() <= b["seconds"].get<double>());
        CHECK(a["rms_rel_error"].get<double>() > b["rms_rel_error"].get<double>());
    }
    for (const char* name : {"draft", "default", "high"}) {
        INFO(name);
        const std::size_t run = acc["room"]["presets"][name]["run"].get<std::size_t>();
        CHECK(std::find(front.begin(), front.end(), run) != front.end());
    }
    // The Cornell box at the draft and default presets against the path tracer: the default is the
    // more accurate (measured 5.8% and 2.3%).
    const json& cornell = acc["cornell"]["runs"];
    REQUIRE(cornell.size() == 2);
    CHECK(cornell[0]["label"] == "draft");
    CHECK(cornell[1]["label"] == "default");
    CHECK(cornell[0]["pixels"]["rms"].get<double>() < 0.08);
    CHECK(cornell[1]["pixels"]["rms"].get<double>() < 0.03);
    CHECK(cornell[1]["pixels"]["rms"].get<double>() < cornell[0]["pixels"]["rms"].get<double>());
    CHECK(cornell[1]["gather_points"].get<long>() > 0);
    CHECK(cornell[1]["faces"].size() >= 10);
    // Run from elsewhere, the missing reference is one line and exit 2.
    const RunResult away = run_hemirad(dir, {"bench", "--accuracy", "--quick"});
    CHECK(away.code == 2);
    check_one_line(away.err);
    CHECK(away.err.find("reference.json") != std::string::npos);
    // Options that do not go together.
    const auto bad = [&](const std::vector<std::string>& args) {
        const RunResult b = run_hemirad(dir, args);
        CHECK(b.code == 2);
        check_one_line(b.err);
    };
    bad({"bench", "--quick", "procedural:100"});
    bad({"bench", "--accuracy", "procedural:100"});
}

namespace {

// Mean over all pixels and channels of |a − b| in 8-bit display steps.
double mean_display_difference(const ImageData& a, const ImageData& b) {
    REQUIRE(a.pixels.size() == b.pixels.size());
    double sum = 0.0;
    for (std::size_t i = 0; i < a.pixels.size(); ++i) sum += std::abs(double(a.pixels[i]) - double(b.pixels[i])) * 255.0;
    return sum / double(a.pixels.size());
}

// The mesh averages of a report by name.
std::map<std::string, std::array<double, 3>> averages(const json& report) {
    std::map<std::string, std::array<double, 3>> out;
    for (const json& m : report.at("meshes"))
        out[m.at("name").get<std::string>()] = {m.at("radiosity")[0].get<double>(), m.at("radiosity")[1].get<double>(),
                                                m.at("radiosity")[2].get<double>()};
    return out;
}

}  // namespace

TEST_CASE("effects: the empty room skips occlusion and colour and still matches the independent reference", "[cli]") {
    // scenes/empty_room.gltf is the room of src/bench/room_reference.h, grey: solved there with exact
    // form factors on 0.2 m cells (surface averages within ~0.02% of converged).
    hemirad::bench::Room room;
    for (auto& rho : room.rho) rho = glm::dvec3(0.7);
    room.rho[int(hemirad::bench::Surface::floor)] = glm::dvec3(0.5);
    room.rho[int(hemirad::bench::Surface::light)] = glm::dvec3(0.8);
    const hemirad::bench::RoomSolution reference = hemirad::bench::solve_room(room, 0.2);

    TempDir dir;
    const fs::path scene = kSourceDir / "scenes" / "empty_room.gltf";
    const json planned = bake_ok(dir, scene, dir / "planned", {"--quiet", "--image-width", "32"});
    const json forced = bake_ok(dir, scene, dir / "forced",
                                {"--quiet", "--image-width", "32", "--device", "ref", "--effects", "occlusion=on,colour=on"});
    const json& effects = planned.at("effects");
    CHECK_FALSE(effects.at("occlusion").at("on").get<bool>());
    CHECK_FALSE(effects.at("colour").at("on").get<bool>());
    CHECK(planned.at("device").at("backend") == "analytic");
    CHECK(forced.at("effects").at("occlusion").at("forced").get<bool>());
    CHECK(forced.at("device").at("backend") == "ref");

    // Measured: the exact form factors are within 0.054% of the reference on every surface (what is
    // left is the elements' size), the hemicube within 0.092%: skipping the depth test and two of
    // the three channels costs nothing measurable.
    const auto a = averages(planned), b = averages(forced);
    for (int s = 0; s < hemirad::bench::kSurfaceCount; ++s) {
        const std::string name = hemirad::bench::surface_name(hemirad::bench::Surface(s));
        const double want = reference.average(hemirad::bench::Surface(s)).x;
        REQUIRE(a.count(name) == 1);
        CAPTURE(name, want, a.at(name)[0], b.at(name)[0]);
        CHECK(std::abs(a.at(name)[0] / want - 1.0) < 0.005);
        CHECK(std::abs(b.at(name)[0] / want - 1.0) < 0.01);
        CHECK(a.at(name)[1] == a.at(name)[0]);  // one channel solved, copied
        CHECK(a.at(name)[2] == a.at(name)[0]);
    }
}

TEST_CASE("effects: stopping at the threshold changes the image less than the hemicube's own noise", "[cli]") {
    // Progressive shooting stopped by the convergence rule, against shooting on until 1e-6 is left,
    // and against another seed (other hemicube rotations) shot out as far: the early stop must
    // change the rendered image (8-bit, tone mapped) much less than the noise of the form factors.
    TempDir dir;
    const std::vector<std::string> args = {"--quiet", "--quality", "draft", "--solver", "progressive",
                                           "--image-width", "160"};
    const json stopped = bake_ok(dir, kCornellBox, dir / "stopped", concat(args, {"--effects", "refinement=off"}));
    const json full = bake_ok(dir, kCornellBox, dir / "full", concat(args, {"--effects", "refinement=off,convergence=off"}));
    const json other = bake_ok(dir, kCornellBox, dir / "other",
                               concat(args, {"--effects", "refinement=off,convergence=off", "--seed", "5"}));
    CHECK(stopped.at("effects").at("convergence").at("on").get<bool>());
    CHECK_FALSE(full.at("effects").at("convergence").at("on").get<bool>());
    CHECK(full.at("passes").get<long>() > 2 * stopped.at("passes").get<long>());
    const double early = mean_display_difference(read_image(dir / "stopped" / "render.png"), read_image(dir / "full" / "render.png"));
    const double noise = mean_display_difference(read_image(dir / "other" / "render.png"), read_image(dir / "full" / "render.png"));
    // Measured: 0.25 display steps against 2.3.
    CAPTURE(early, noise);
    CHECK(early < 0.25 * noise);
}

TEST_CASE("effects and solver options that cannot go together exit 2 with one line", "[cli]") {
    TempDir dir;
    const fs::path out = dir / "out";
    const auto bake = [&](std::vector<std::string> extra) {
        return concat({"bake", kCornellBox.string(), "-o", out.string(), "--quiet"}, extra);
    };
    expect_bad_input(dir, bake({"--effects", "occlusion=maybe"}), out, "maybe");
    expect_bad_input(dir, bake({"--effects", "shadows=off"}), out, "shadows");
    expect_bad_input(dir, bake({"--effects", "occlusion=off,occlusion=on"}), out, "occlusion");
    expect_bad_input(dir, bake({"--solver", "matrix", "--preview-every", "5"}), out, "--preview-every");
    expect_bad_input(dir, bake({"--solver", "progressive", "--effects", "interreflection=off"}), out, "interreflection");
    expect_bad_input(dir, bake({"--verify", "--device", "ref", "--effects", "occlusion=off"}), out, "--verify");
    expect_bad_input(dir, bake({"--solver", "gauss"}), out, "--solver");
}

namespace {

// Bakes `settings` whole, then twice again killed with SIGKILL (nothing can be cleaned up) at
// `delays` after the first checkpoint (every K = `every`) is on disk, each resumed into the
// killed bake's directory: every resumed bake ends with exactly the whole bake's numbers (killed
// after the solve, while refining or writing, it resumes from the finished solve). Returns the
// whole bake's report; the first resume must have started part-way through the solve.
json check_kill_and_resume(const TempDir& dir, const std::string& name, const std::vector<std::string>& settings,
                           const std::string& every, const std::vector<std::string>& delays) {
    const json full = bake_ok(dir, kClosedRoom, dir / (name + "_full"), settings);
    const std::string full_bin = read_text(dir / (name + "_full") / "baked.bin");
    for (const std::string& delay : delays) {
        INFO(name << ", killed " << delay << " s after the first checkpoint");
        const std::string ck = (dir / (name + "_ck" + delay)).string();
        const fs::path out = dir / (name + "_killed" + delay);
        std::string script = shell_quote(HEMIRAD_EXE);
        for (const std::string& a :
             concat({"bake", kClosedRoom.string(), "-o", out.string(), "--checkpoint", ck, "--checkpoint-every", every},
                    settings))
            script += " " + shell_quote(a);
        script += " & pid=$!; i=0; while [ ! -e " + shell_quote(ck) +
                  " ] && [ $i -lt 400 ]; do sleep 0.02; i=$((i+1)); done; sleep " + delay +
                  "; kill -KILL $pid; wait $pid";
        const RunResult killed = run_shell(dir, script);
        REQUIRE(fs::exists(ck));
        CHECK_FALSE(fs::exists(out / "report.json"));
        // The killed bake's staging directory is left behind; the resumed bake, into the same
        // directory as a user would, clears it (its process is gone).
        const auto staging = [&out] {
            std::size_t n = 0;
            for (const auto& e : fs::directory_iterator(out))
                n += e.path().filename().string().rfind(".hemirad-tmp-", 0) == 0 ? 1 : 0;
            return n;
        };
        CHECK(staging() == 1);
        const json resumed =
            bake_ok(dir, kClosedRoom, out, concat({"--resume", ck, "--checkpoint", ck, "--checkpoint-every", every}, settings));
        CHECK(staging() == 0);
        // Killed after the solve, the checkpoint holds a later stage (the solved, refined or
        // gathered light), and the bake goes on from there.
        const bool part_way = resumed.contains("resumed_from_pass");
        if (!part_way) CHECK(resumed.at("resumed").at("from") != "solving");
        const long from = part_way ? resumed.at("resumed_from_pass").get<long>() : full.at("passes").get<long>();
        CAPTURE(killed.code, from);
        CHECK(from > 0);
        CHECK(from <= full.at("passes").get<long>());
        if (delay == delays.front()) CHECK(from < full.at("passes").get<long>());
        CHECK(resumed.at("passes") == full.at("passes"));
        CHECK(resumed.at("meshes") == full.at("meshes"));
        CHECK(resumed.at("energy") == full.at("energy"));
        CHECK(read_text(out / "baked.bin") == full_bin);
    }
    return full;
}

}  // namespace

TEST_CASE("a bake killed part-way resumes from its checkpoint and ends with the same numbers", "[cli]") {
    TempDir dir;
    const std::vector<std::string> settings = {"--hemicube", "32", "--patch-size", "0.5", "--element-size", "0.25",
                                               "--threshold", "1e-6", "--max-passes", "2000", "--solver",
                                               "progressive", "--image-width", "32", "--quiet"};
    const json full = check_kill_and_resume(dir, "progressive", settings, "100", {"0.1", "0.5"});
    REQUIRE(full.at("passes").get<long>() == 2000);
    const std::string full_bin = read_text(dir / "progressive_full" / "baked.bin");

    // The finished stages are checkpointed too (2000 is no multiple of 300): the last, the
    // gathered light, resumed, goes straight to the outputs.
    const std::string ck_full = (dir / "ck_full").string();
    bake_ok(dir, kClosedRoom, dir / "checkpointed", concat({"--checkpoint", ck_full, "--checkpoint-every", "300"}, settings));
    const json finished = bake_ok(dir, kClosedRoom, dir / "finished", concat({"--resume", ck_full}, settings));
    CHECK(finished.at("resumed").at("from") == "gathered");
    CHECK(finished.at("passes") == 2000);
    CHECK(read_text(dir / "finished" / "baked.bin") == full_bin);

    // The matrix solver's checkpoints hold the rows shot so far (the reference engine, slower,
    // leaves time to kill it between its batches of 64 rows).
    const std::vector<std::string> matrix = {"--hemicube", "96", "--patch-size", "0.5", "--element-size", "0.25",
                                             "--solver", "matrix", "--device", "ref", "--image-width", "32", "--quiet"};
    const json rows = check_kill_and_resume(dir, "matrix", matrix, "50", {"0.05", "0.5"});
    CHECK(rows.at("passes").get<long>() > 128);  // rows: more than two batches
    // A checkpoint of the one solver is refused by the other.
    expect_bad_input(dir, concat({"bake", kClosedRoom.string(), "-o", (dir / "crossed").string(), "--resume",
                                  (dir / "matrix_ck0.05").string()},
                                 settings),
                     dir / "crossed", "another bake");

    // A checkpoint resumes only its own bake; anything else is refused, naming the file.
    const fs::path ck = dir / "progressive_ck0.1";
    const fs::path out = dir / "refused";
    const auto bake = [&](std::vector<std::string> extra) {
        return concat(concat({"bake", kClosedRoom.string(), "-o", out.string()}, settings), extra);
    };
    expect_bad_input(dir, bake({"--resume", ck.string(), "--seed", "7"}), out, "another bake");
    expect_bad_input(dir, bake({"--resume", (dir / "progressive_full" / "report.json").string()}), out,
                     "not a hemirad checkpoint");
    expect_bad_input(dir, bake({"--resume", (dir / "missing").string()}), out, "missing");
    const std::string whole = read_text(ck);
    write_text(dir / "cut", whole.substr(0, whole.size() / 2));
    expect_bad_input(dir, bake({"--resume", (dir / "cut").string()}), out, "damaged");
    // One bit flipped in the state (a disk's error): whole in length and end marker, refused all the same.
    std::string flipped = whole;
    flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x10);
    write_text(dir / "flipped", flipped);
    expect_bad_input(dir, bake({"--resume", (dir / "flipped").string()}), out, "checksum");
}

TEST_CASE("the corpus of malformed scenes: each is exit 2 with one line naming the file and the problem", "[cli]") {
    // tests/corpus (made by tests/corpus/make_corpus.py): truncated and invalid JSON, an empty
    // file, glTF 1.0, a missing buffer, a data URI that does not decode, accessors and buffer
    // views past their ends, an index out of range, NaN and Inf positions, reflectance below 0
    // and above 1, negative emission, no emitter, no geometry, only lines, counts that would
    // exhaust memory, a .glb with a bad magic and a truncated one; and hostile ones: an empty .glb,
    // JSON nested 20,000 deep (.gltf and .glb), a .glb header declaring more than the file holds,
    // binary zeros as a .gltf, emission beyond what the outputs hold, invalid cameras, and
    // textures whose image is missing, undecodable or absent.
    const fs::path corpus = kSourceDir / "tests" / "corpus";
    const json manifest = read_json(corpus / "manifest.json");
    REQUIRE(manifest.size() >= 20);
    TempDir dir;
    for (const json& c : manifest) {
        const std::string file = c.at("file").get<std::string>();
        INFO("corpus file " << file);
        const fs::path out = dir / ("out_" + file);
        std::vector<std::string> args = {"--quiet"};  // and any the case names (--strict-textures)
        for (const json& a : c.value("args", json::array())) args.push_back(a.get<std::string>());
        const RunResult r = expect_bad_input(dir, bake_args(corpus / file, out, args), out, file);
        CHECK(r.err.find(c.at("error_contains").get<std::string>()) != std::string::npos);
    }
}

// ---------------------------------------------------------------------------------------
// Hostile input: files and values made to crash a bake, hang it, or make it destroy or silently
// misread something. Each is exit 2 with one line naming the file or option, nothing written.

namespace {

// In front of a run that must not hang (a FIFO, a device): a regression then fails the test with
// exit 137 instead of blocking the suite.
const std::string kNoHang = "timeout -s KILL 60 ";

// closed_room.gltf with `extras` arrays nested `depth` deep.
std::string deeply_nested(int depth) {
    const std::string text = read_text(kClosedRoom);
    const std::size_t brace = text.find('{');
    return text.substr(0, brace + 1) + "\"extras\": " + std::string(std::size_t(depth), '[') +
           std::string(std::size_t(depth), ']') + ", " + text.substr(brace + 1);
}

void append_u32(std::string& bytes, std::uint32_t value) {
    for (int i = 0; i < 4; ++i) bytes += static_cast<char>((value >> (8 * i)) & 0xffu);
}

// A .glb holding `json` as its one chunk.
std::string glb_of(std::string json) {
    while (json.size() % 4 != 0) json += ' ';
    std::string glb = "glTF";
    append_u32(glb, 2);
    append_u32(glb, static_cast<std::uint32_t>(20 + json.size()));
    append_u32(glb, static_cast<std::uint32_t>(json.size()));
    glb += "JSON";
    return glb + json;
}

// closed_room with material 0's base colour texture read from `uri`.
json with_texture(const std::string& uri) {
    json g = read_json(kClosedRoom);
    g["images"] = json::array({{{"uri", uri}}});
    g["textures"] = json::array({{{"source", 0}}});
    g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    return g;
}

void make_fifo(const fs::path& path) { REQUIRE(::mkfifo(path.c_str(), 0600) == 0); }

}  // namespace

TEST_CASE("hostile input: deep JSON, FIFOs, devices and directories are exit 2 with one line, never a hang", "[cli][hostile]") {
    TempDir dir;
    const fs::path out = dir / "never";

    SECTION("extras nested 20,000 deep in a .gltf (a stack overflow in the JSON parser)") {
        const fs::path file = dir / "deep.gltf";
        write_text(file, deeply_nested(20000));
        const RunResult r = expect_bad_input(dir, bake_args(file, out), out, "deep.gltf");
        CHECK(r.err.find("512 levels") != std::string::npos);
    }
    SECTION("JSON nested 20,000 deep in a .glb's JSON chunk") {
        const fs::path file = dir / "deep.glb";
        write_text(file, glb_of(deeply_nested(20000)));
        const RunResult r = expect_bad_input(dir, bake_args(file, out), out, "deep.glb");
        CHECK(r.err.find("512 levels") != std::string::npos);
    }
    SECTION("nesting within the limit, and brackets inside strings, load") {
        json g = read_json(kClosedRoom);
        json nested = json::array();
        for (int i = 0; i < 500; ++i) nested = json::array({nested});
        g["extras"] = {{"deep", nested}, {"text", std::string(2000, '[') + "\\\"{"}};
        write_json(dir / "nested_ok.gltf", g);
        bake_ok(dir, dir / "nested_ok.gltf", dir / "ok");
    }
    SECTION("a FIFO as the scene (open() used to wait for a writer, deaf to SIGINT)") {
        make_fifo(dir / "fifo.gltf");
        const RunResult r = expect_bad_input(dir, bake_args(dir / "fifo.gltf", out), out, "fifo.gltf", kNoHang);
        CHECK(r.err.find("FIFO") != std::string::npos);
    }
    SECTION("a device as the scene") {
        fs::create_symlink("/dev/zero", dir / "zero.glb");
        const RunResult r = expect_bad_input(dir, bake_args(dir / "zero.glb", out), out, "zero.glb", kNoHang);
        CHECK(r.err.find("not a regular file") != std::string::npos);
    }
    SECTION("a FIFO as a buffer's uri") {
        json g = read_json(kClosedRoom);
        g["buffers"].push_back({{"uri", "fifo.bin"}, {"byteLength", 4}});
        write_json(dir / "fifo_buffer.gltf", g);
        make_fifo(dir / "fifo.bin");
        const RunResult r = expect_bad_input(dir, bake_args(dir / "fifo_buffer.gltf", out), out, "fifo.bin", kNoHang);
        CHECK(r.err.find("FIFO") != std::string::npos);
    }
    SECTION("a FIFO as an image's uri") {
        write_json(dir / "fifo_image.gltf", with_texture("fifo.png"));
        make_fifo(dir / "fifo.png");
        const RunResult r = expect_bad_input(dir, bake_args(dir / "fifo_image.gltf", out, concat(kFast, {"--strict-textures"})),
                                             out, "fifo.png", kNoHang);
        CHECK(r.err.find("FIFO") != std::string::npos);
        // Without --strict-textures the image is one that cannot be used: a warning, never a hang.
        const RunResult lenient = run_hemirad(dir, bake_args(dir / "fifo_image.gltf", dir / "lenient"), kNoHang);
        INFO("stderr: [" << lenient.err << "]");
        CHECK(lenient.code == 0);
        CHECK(lenient.err.find("FIFO") != std::string::npos);
    }
    SECTION("a FIFO or a directory as --resume (a directory was an internal error)") {
        make_fifo(dir / "fifo.ck");
        fs::create_directories(dir / "ck_dir");
        for (const std::string ck : {"fifo.ck", "ck_dir"}) {
            INFO(ck);
            const RunResult r = expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--resume", ck})), out,
                                                 ck, kNoHang);
            CHECK(r.err.find("not a regular file") != std::string::npos);
            CHECK(r.err.find("internal error") == std::string::npos);
        }
    }
    SECTION("a FIFO or a directory as --checkpoint") {
        make_fifo(dir / "fifo.ck");
        fs::create_directories(dir / "ck_dir");
        for (const std::string ck : {"fifo.ck", "ck_dir"}) {
            INFO(ck);
            expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--checkpoint", ck})), out, ck, kNoHang);
        }
        CHECK(fs::is_fifo(dir / "fifo.ck"));
        CHECK(fs::is_directory(dir / "ck_dir"));
    }
}

TEST_CASE("hostile input: a 2 GiB file that is not glTF is refused from its first bytes", "[cli][hostile]") {
    // Sparse files: nothing is stored, and a loader that read one whole would take seconds and 2 GiB.
    TempDir dir;
    const fs::path out = dir / "never";
    constexpr std::uintmax_t k2GiB = std::uintmax_t{2} << 30;
    const auto sparse = [&](const std::string& name, const std::string& head) {
        write_text(dir / name, head);
        fs::resize_file(dir / name, k2GiB);
        return dir / name;
    };
    const auto refused = [&](const fs::path& file, const std::string& why) {
        INFO(file);
        const RunResult r = expect_bad_input(dir, bake_args(file, out), out, file.filename().string(), kNoHang);
        CHECK(r.err.find(why) != std::string::npos);
    };
    refused(sparse("zeros.glb", ""), "magic");
    refused(sparse("zeros.gltf", ""), "not JSON");
    refused(sparse("brace.gltf", "{"), "above the limit");  // JSON by its first byte, but 2 GiB of it
}

TEST_CASE("hostile input: a NaN option is refused before any work", "[cli][hostile]") {
    // --threshold nan used to run the whole bake before failing on its report; --patch-size nan
    // was silently ignored. Every number option, every spelling: test_cli_options.cpp.
    TempDir dir;
    const fs::path out = dir / "never";
    for (const std::string option : {"--threshold", "--patch-size"}) {
        INFO(option);
        const RunResult r = expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {option, "nan"})), out, option);
        CHECK(r.err.find("not a finite number") != std::string::npos);
    }
    // Finite but so small the mesh would exhaust the memory (1e-300 was an internal error).
    for (const std::string option : {"--element-size", "--patch-size"}) {
        INFO(option);
        const RunResult r = expect_bad_input(dir, bake_args(kClosedRoom, out, {option, "1e-300", "--quiet"}), out, option);
        CHECK(r.err.find("needs less") != std::string::npos);
    }
}

TEST_CASE("hostile input: --checkpoint replaces only a hemirad checkpoint, never the scene or another file", "[cli][hostile]") {
    TempDir dir;
    const fs::path out = dir / "never";
    const fs::path scene = dir / "scene.gltf";
    write_text(scene, read_text(kClosedRoom));
    const std::string before = read_text(scene);
    const RunResult r =
        expect_bad_input(dir, bake_args(scene, out, concat(kFast, {"--checkpoint", scene.string()})), out, "scene.gltf");
    CHECK(r.err.find("not a hemirad checkpoint") != std::string::npos);
    CHECK(read_text(scene) == before);
    expect_bad_input(dir, bake_args(scene, out, concat(kFast, {"--checkpoint", (dir / "no_dir" / "ck").string()})), out,
                     "no_dir");
    // A checkpoint is replaced by the next bake's.
    const fs::path ck = dir / "ck";
    bake_ok(dir, scene, dir / "first", concat(kFast, {"--checkpoint", ck.string()}));
    const std::string first = read_text(ck);
    REQUIRE(first.rfind("hemirad checkpoint\n", 0) == 0);
    // Another seed rotates the hemicubes otherwise, so its state differs: the file must now hold it.
    bake_ok(dir, scene, dir / "second", concat(kFast, {"--checkpoint", ck.string(), "--seed", "2"}));
    const std::string second = read_text(ck);
    CHECK(second.rfind("hemirad checkpoint\n", 0) == 0);
    CHECK(second != first);
}

TEST_CASE("hostile input: SIGHUP interrupts a bake as SIGINT does: exit 130, no output, no staging, no previews", "[cli][hostile]") {
    TempDir dir;
    fs::create_directories(dir / "mine");
    write_text(dir / "mine" / "notes.txt", "keep\n");
    const RunResult by_hup = interrupted_bake(dir, "out_hup", "HUP");
    INFO("stderr: " << by_hup.err);
    CHECK(by_hup.code == 130);  // as SIGINT and SIGTERM (README, exit codes)
    CHECK(by_hup.err.find("interrupted") != std::string::npos);
    CHECK(!fs::exists(dir / "out_hup"));
    // Into a directory of the user's: the staging directory and the preview frames go, the user's file stays.
    const RunResult into_mine = interrupted_bake(dir, "mine", "HUP");
    CHECK(into_mine.code == 130);
    CHECK(listing(dir / "mine") == std::set<std::string>{"notes.txt"});
}

TEST_CASE("a bake started with SIGHUP ignored (nohup) survives the hangup and finishes", "[cli][hostile]") {
    TempDir dir;
    const RunResult r = interrupted_bake(dir, "out", "HUP", /*ignore=*/"HUP", /*max_passes=*/300);
    INFO("stderr: " << r.err);
    REQUIRE(r.out.find("signal-sent") != std::string::npos);  // the hangup came while it ran
    CHECK(r.code == 0);
    CHECK(fs::exists(dir / "out" / "report.json"));
}

TEST_CASE("hostile input: a camera's extreme aspect ratio or field of view is clamped with a warning", "[cli][hostile]") {
    // Legal glTF no image can be made from: clamped with a warning (README); invalid values are
    // in the corpus (exit 2).
    TempDir dir;
    json g = read_json(kClosedRoom);
    g["cameras"][0]["perspective"]["aspectRatio"] = 1e-9;
    g["cameras"][0]["perspective"]["yfov"] = 1e-300;
    write_json(dir / "extreme.gltf", g);
    const fs::path out = dir / "out";
    const RunResult r = run_hemirad(dir, bake_args(dir / "extreme.gltf", out));  // kFast: 64 pixels wide
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    CHECK(r.err.find("aspectRatio 1e-09 is outside [0.0625, 16]; using 0.0625") != std::string::npos);
    CHECK(r.err.find("yfov 1e-300 is too narrow") != std::string::npos);
    const json report = read_json(out / "report.json");
    CHECK(report["settings"]["image"] == json::array({64, 1024}));
    CHECK(report["warnings"].size() == 2);
    CHECK(read_image(out / "render.png").height == 1024);
    // The image that camera gives at a larger width would be too high: the option is named.
    expect_bad_input(dir,
                     bake_args(dir / "extreme.gltf", dir / "never",
                               {"--hemicube", "32", "--patch-size", "1.0", "--image-width", "2000", "--quiet"}),
                     dir / "never", "--image-width");
}

TEST_CASE("hostile input: a texture's image that is missing, unreadable or undecodable is exit 2 naming it under "
          "--strict-textures, else one warning naming it", "[cli][hostile]") {
    // One rule (README): with --strict-textures the image of a base colour or emissive texture
    // must be read and decoded, else the bake stops naming it; without it the bake goes on with
    // the material's factors and one warning naming the image and the problem. (A FIFO and a
    // directory: above and in the corpus.)
    TempDir dir;
    const fs::path out = dir / "never";
    int run = 0;
    const auto refused = [&](const std::string& uri, const std::string& why) {
        INFO(uri);
        write_json(dir / "textured.gltf", with_texture(uri));
        const RunResult r = expect_bad_input(dir, bake_args(dir / "textured.gltf", out, concat(kFast, {"--strict-textures"})),
                                             out, uri, kNoHang);
        CHECK(r.err.find("baseColorTexture") != std::string::npos);
        CHECK(r.err.find(why) != std::string::npos);
        const fs::path lenient = dir / ("lenient" + std::to_string(run++));
        const json report = bake_ok(dir, dir / "textured.gltf", lenient);
        std::size_t named = 0;
        for (const json& w : report["warnings"]) {
            const std::string text = w.get<std::string>();
            named += text.find(uri) != std::string::npos && text.find(why) != std::string::npos &&
                     text.find("1 material (") != std::string::npos && text.find("--strict-textures") != std::string::npos;
        }
        CHECK(named == 1);
    };
    refused("missing.png", "No such file");
    write_text(dir / "garbage.png", "not an image\n");
    refused("garbage.png", "not a PNG, JPEG or WebP image");
    {  // a PNG cut short: libpng's own complaint must not become a second line
        auto image = OIIO::ImageOutput::create("png");
        REQUIRE(image);
        const OIIO::ImageSpec spec(64, 64, 3, OIIO::TypeDesc::UINT8);
        std::vector<unsigned char> noise(64 * 64 * 3);
        for (std::size_t i = 0; i < noise.size(); ++i) noise[i] = static_cast<unsigned char>((i * 2654435761u) >> 13);
        REQUIRE(image->open((dir / "whole.png").string(), spec));
        REQUIRE(image->write_image(OIIO::TypeDesc::UINT8, noise.data()));
        REQUIRE(image->close());
        const std::string png = read_text(dir / "whole.png");
        write_text(dir / "cut.png", png.substr(0, png.size() / 2));
    }
    refused("cut.png", "does not decode");
    // Unreadable by permission: root reads it all the same, so only where that bit is honoured.
    write_text(dir / "secret.png", "whatever\n");
    fs::permissions(dir / "secret.png", fs::perms::none);
    if (::geteuid() != 0) refused("secret.png", "Permission denied");
    else WARN("running as root, which reads a file of mode 000: its case is skipped");
}

TEST_CASE("textures: a decodable one is used and an image no texture uses does not matter", "[cli][hostile]") {
    TempDir dir;
    {
        auto image = OIIO::ImageOutput::create("png");
        REQUIRE(image);
        const OIIO::ImageSpec spec(4, 2, 3, OIIO::TypeDesc::UINT8);
        const std::vector<unsigned char> pixels(4 * 2 * 3, 64);
        REQUIRE(image->open((dir / "dark.png").string(), spec));
        REQUIRE(image->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
        image->close();
    }
    write_json(dir / "dark.gltf", with_texture("dark.png"));
    json unused = read_json(kClosedRoom);
    unused["images"] = json::array({{{"uri", "missing.png"}}});
    write_json(dir / "unused.gltf", unused);
    bake_ok(dir, dir / "dark.gltf", dir / "dark");
    const json plain = bake_ok(dir, dir / "unused.gltf", dir / "plain");
    CHECK(plain["warnings"].empty());  // not even a warning: no material uses it
    CHECK(read_text(dir / "plain" / "baked.bin") != read_text(dir / "dark" / "baked.bin"));  // the walls darkened
}

namespace {

// Bakes the closed room on OpenCL (kFast), then once with each environment of `environments`
// (assignments in front of the command), and checks that every one of those bakes on OpenCL and
// writes the same baked.bin.
void check_environments_keep_bytes(const TempDir& dir, const std::vector<std::string>& environments) {
    const std::vector<std::string> on_opencl = concat(kFast, {"--device", "opencl"});
    bake_ok(dir, kClosedRoom, dir / "default", on_opencl);
    const std::string reference = read_text(dir / "default" / "baked.bin");
    int run = 0;
    for (const std::string& env : environments) {
        INFO(env);
        const fs::path out = dir / ("varied" + std::to_string(run++));
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, out, on_opencl), env);
        INFO("stderr: " << r.err);
        REQUIRE(r.code == 0);
        CHECK(read_json(out / "report.json")["device"]["backend"] == "opencl");
        CHECK(read_text(out / "baked.bin") == reference);
    }
}

}  // namespace

TEST_CASE("HEMIRAD_OPENCL_OPTIONS: knob overrides reach the host too (the same bytes) and values the kernels cannot take exit 2", "[cli][opencl][hostile]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    TempDir dir;
    // -DHEMIRAD_TILE=8 and many counter copies used to corrupt the heap: the host sized the
    // buffers with its own knobs. Now the host takes the overrides, and the results are the same.
    check_environments_keep_bytes(dir, {"HEMIRAD_OPENCL_OPTIONS=" + shell_quote("-DHEMIRAD_TILE=8") + " ",
                                        "HEMIRAD_OPENCL_OPTIONS=" +
                                            shell_quote("-DHEMIRAD_COUNT_COPIES=64 -D HEMIRAD_WG=32") + " "});
    // Refused before any shot, with the variable and the knob named; `auto` does not fall back.
    const fs::path out = dir / "never";
    // (Every knob and spelling: "opencl: -D overrides of the host's knobs …" in test_opencl.cpp.)
    for (const auto& [options, device] : std::vector<std::pair<std::string, std::string>>{
             {"-DHEMIRAD_COUNT_COPIES=1000", "opencl"}, {"-DHEMIRAD_COUNT_COPIES=1000", "auto"}, {"-UHEMIRAD_TILE", "auto"}}) {
        INFO(options << " with --device " << device);
        const RunResult r = expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--device", device})), out,
                                             "HEMIRAD_OPENCL_OPTIONS",
                                             "HEMIRAD_OPENCL_OPTIONS=" + shell_quote(options) + " ");
        const std::string knob = options.substr(2, options.find('=') == std::string::npos ? std::string::npos
                                                                                          : options.find('=') - 2);
        CHECK(r.err.find(knob) != std::string::npos);
    }
}

TEST_CASE("HEMIRAD_OCCLUSION and HEMIRAD_OCCLUDER_SHARE: the same bytes either way, other values exit 2", "[cli][opencl][hostile]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    TempDir dir;
    check_environments_keep_bytes(dir, {"HEMIRAD_OCCLUSION=0 ", "HEMIRAD_OCCLUSION=1 HEMIRAD_OCCLUDER_SHARE=1 "});
    const std::vector<std::string> on_opencl = concat(kFast, {"--device", "opencl"});
    const fs::path out = dir / "never";
    for (const auto& [variable, value] : std::vector<std::pair<std::string, std::string>>{
             {"HEMIRAD_OCCLUSION", "yes"}, {"HEMIRAD_OCCLUDER_SHARE", "0"}, {"HEMIRAD_OCCLUDER_SHARE", "4x"}}) {
        INFO(variable << "=" << value);
        expect_bad_input(dir, bake_args(kClosedRoom, out, on_opencl), out, variable, variable + "=" + value + " ");
    }
}

TEST_CASE("hostile input: a name with a newline or a terminal escape still gives one line", "[cli][hostile]") {
    TempDir dir;
    const fs::path out = dir / "never";
    json g = read_json(kClosedRoom);
    g["materials"][0]["name"] = "evil\nsecond line\x1b[31m";
    g["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = {1.5, 0.5, 0.5, 1.0};
    write_json(dir / "names.gltf", g);
    const RunResult r = expect_bad_input(dir, bake_args(dir / "names.gltf", out), out, "evil\\x0asecond line\\x1b[31m");
    CHECK(r.err.find('\x1b') == std::string::npos);
    // An option's value as well.
    expect_bad_input(dir, bake_args(kClosedRoom, out, concat(kFast, {"--camera", "a\nb"})), out, "a\\x0ab");
}

TEST_CASE("hostile input: a directory where an output file goes, or a file where previews go, is exit 2 before any work", "[cli][hostile]") {
    TempDir dir;
    const fs::path out = dir / "mine";
    fs::create_directories(out / "report.json");
    write_text(out / "preview", "my file\n");
    for (const auto& [extra, obstacle] : std::vector<std::pair<std::vector<std::string>, std::string>>{
             {kFast, "report.json"}, {concat(kFast, {"--preview-every", "50"}), "preview"}}) {
        INFO(obstacle);
        if (obstacle == "preview") fs::remove(out / "report.json");
        const RunResult r = run_hemirad(dir, bake_args(kClosedRoom, out, extra));
        INFO("stderr: " << r.err);
        CHECK(r.code == 2);  // was exit 1, "cannot move report.json into place", at the very end
        check_one_line(r.err);
        CHECK(r.err.find(obstacle) != std::string::npos);
    }
    CHECK(listing(out) == std::set<std::string>{"preview"});
    CHECK(read_text(out / "preview") == "my file\n");
}

TEST_CASE("hostile input: emission at the loader's limit bakes with every output finite", "[cli][hostile]") {
    // 1e30 passes the loader (1e100 is in the corpus, exit 2); render.exr was half float, so
    // anything brighter than 65504 was written as inf while the report said all was finite.
    TempDir dir;
    json g = read_json(kClosedRoom);
    for (auto& material : g["materials"])
        if (material.contains("emissiveFactor"))
            material["extensions"] = {{"KHR_materials_emissive_strength", {{"emissiveStrength", 1e30}}}};
    g["extensionsUsed"] = {"KHR_materials_emissive_strength"};
    write_json(dir / "bright.gltf", g);
    const json report = bake_ok(dir, dir / "bright.gltf", dir / "out");
    CHECK(all_numbers_finite(report));
    const ImageData exr = read_image(dir / "out" / "render.exr");
    CHECK(std::all_of(exr.pixels.begin(), exr.pixels.end(), [](float v) { return std::isfinite(v); }));
    CHECK(*std::max_element(exr.pixels.begin(), exr.pixels.end()) > 1e29f);
}
