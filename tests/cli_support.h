// Running the hemirad executable from tests: scratch directories, /bin/sh runs with captured
// output, and bakes that must succeed, for every test file that checks the real binary.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <OpenImageIO/imageio.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace hemirad::test {

namespace fs = std::filesystem;
using json = nlohmann::json;

inline const fs::path kSourceDir = HEMIRAD_SOURCE_DIR;
inline const fs::path kClosedRoom = kSourceDir / "scenes" / "closed_room.gltf";
inline const fs::path kCornellBox = kSourceDir / "scenes" / "cornell_box.gltf";

// closed_room is about 6.7 m across: large patches keep every bake well under a second.
inline const std::vector<std::string> kFast = {"--hemicube", "32",           "--patch-size", "1.0",
                                        "--element-size", "0.5",      "--max-passes", "200",
                                        "--image-width", "64",        "--quiet"};

inline std::string shell_quote(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

inline std::string read_text(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

inline void write_text(const fs::path& file, const std::string& text) {
    std::ofstream out(file, std::ios::binary);
    out << text;
    REQUIRE(out.good());
}

inline json read_json(const fs::path& file) { return json::parse(read_text(file)); }

inline void write_json(const fs::path& file, const json& j) { write_text(file, j.dump(2)); }

// A fresh, empty directory of this test's own, removed with everything in it at the end.
class TempDir {
public:
    TempDir() {
        static std::atomic<int> counter{0};
        const auto now = std::chrono::steady_clock::now().time_since_epoch().count();
        path_ = fs::temp_directory_path() /
                ("hemirad-cli-test-" + std::to_string(getpid()) + "-" + std::to_string(counter++) + "-" +
                 std::to_string(now));
        fs::create_directories(path_);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    const fs::path& path() const { return path_; }
    fs::path operator/(const std::string& name) const { return path_ / name; }

private:
    fs::path path_;
};

struct RunResult {
    int code = -1;
    std::string out, err;
};

// Runs `sh -c "<script>"` in `cwd`, stdout and stderr captured to files beside (not in) any
// output directory the script names.
inline RunResult run_shell(const TempDir& dir, const std::string& script) {
    static std::atomic<int> counter{0};
    const int n = counter++;
    const fs::path out = dir / ("stdout-" + std::to_string(n) + ".txt");
    const fs::path err = dir / ("stderr-" + std::to_string(n) + ".txt");
    // No automatic checkpoints (bake/stage_checkpoint.h) unless a test asks: the long bakes tests
    // interrupt would leave them in the user's cache, and a later test of the same command
    // would resume them.
    const std::string command = "cd " + shell_quote(dir.path().string()) +
                                " && export HEMIRAD_CHECKPOINT_ABOVE=\"${HEMIRAD_CHECKPOINT_ABOVE-inf}\" && { " + script + " ; } >" +
                                shell_quote(out.string()) + " 2>" + shell_quote(err.string());
    const int status = std::system(command.c_str());  // std::system runs /bin/sh -c "command"
    RunResult r;
    REQUIRE(status != -1);
    REQUIRE(WIFEXITED(status));
    r.code = WEXITSTATUS(status);
    r.out = read_text(out);
    r.err = read_text(err);
    fs::remove(out);
    fs::remove(err);
    return r;
}

// Runs the hemirad executable with `args` (each quoted), working directory `dir`, with the
// environment assignments `env` ("NAME=value ", unquoted) in front.
inline RunResult run_hemirad(const TempDir& dir, const std::vector<std::string>& args, const std::string& env = "") {
    std::string script = env + shell_quote(HEMIRAD_EXE);
    for (const auto& a : args) script += " " + shell_quote(a);
    return run_shell(dir, script);
}

inline std::vector<std::string> concat(std::vector<std::string> a, const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

inline std::vector<std::string> bake_args(const fs::path& scene, const fs::path& out,
                                   const std::vector<std::string>& extra = kFast) {
    return concat({"bake", scene.string(), "-o", out.string()}, extra);
}

// An image file read back as floats (PNG values in [0, 1]; EXR linear).
struct ImageData {
    int width = 0, height = 0, channels = 0;
    std::vector<float> pixels;
};

inline ImageData read_image(const fs::path& file) {
    ImageData image;
    auto in = OIIO::ImageInput::open(file.string());
    INFO("OpenImageIO: " << OIIO::geterror());
    REQUIRE(in);
    const OIIO::ImageSpec& spec = in->spec();
    image.width = spec.width;
    image.height = spec.height;
    image.channels = spec.nchannels;
    image.pixels.resize(std::size_t(spec.width) * std::size_t(spec.height) * std::size_t(spec.nchannels));
    REQUIRE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.pixels.data()));
    in->close();
    return image;
}

// Runs a bake that must succeed.
inline json bake_ok(const TempDir& dir, const fs::path& scene, const fs::path& out,
             const std::vector<std::string>& extra = kFast) {
    const RunResult r = run_hemirad(dir, bake_args(scene, out, extra));
    INFO("stderr: " << r.err);
    REQUIRE(r.code == 0);
    REQUIRE(fs::is_regular_file(out / "report.json"));
    // A NaN or Inf would be written as null: no bake of these tests may have one.
    CHECK(read_text(out / "report.json").find("null") == std::string::npos);
    return read_json(out / "report.json");
}

}  // namespace hemirad::test
