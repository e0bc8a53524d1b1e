// Seeing the result: --look-from/--look-at/--fov for a view the file lacks, --exposure, and a
// progress report in logs (--progress when stderr is not a terminal).
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <string>

#include "cli_support.h"
#include "image_artifacts.h"

namespace {

using namespace hemirad::test;

// The pixel at the centre of an image, channel c.
float centre(const ImageData& image, int c) {
    const std::size_t x = std::size_t(image.width / 2), y = std::size_t(image.height / 2);
    return image.pixels[(y * std::size_t(image.width) + x) * std::size_t(image.channels) + std::size_t(c)];
}

}  // namespace

TEST_CASE("look-from and look-at render a view the file lacks, --fov narrows it", "[cli][view]") {
    TempDir dir;
    // From the Cornell box's floor straight up at its light, a narrow field of view: the light
    // fills the middle of the image, whose linear value is its radiosity, its emission 17 (red)
    // and what it reflects (reflectance 0.78) of the little light it receives.
    const json report = bake_ok(dir, kCornellBox, dir / "up",
                                concat(kFast, {"--look-from", "0.278,0.05,0.28", "--look-at", "0.278,0.5,0.28",
                                               "--fov", "10"}));
    CHECK(report["settings"]["camera"] == "look-from");
    const ImageData exr = read_image(dir / "up" / "render.exr");
    CHECK(exr.width * 3 == exr.height * 4);  // 4:3
    CHECK(centre(exr, 0) >= 17.0f);
    CHECK(centre(exr, 0) < 17.0f * 1.2f);
    CHECK(centre(exr, 2) >= 4.0f);
    // The file's camera sees the back wall in the middle instead: far dimmer than the light.
    bake_ok(dir, kCornellBox, dir / "own");
    const ImageData own = read_image(dir / "own" / "render.exr");
    CHECK(centre(own, 0) < 2.0f);
}

TEST_CASE("the exposure option sets render.png's exposure in stops, and the report says which it used", "[cli][view]") {
    TempDir dir;
    const json automatic = bake_ok(dir, kCornellBox, dir / "auto");
    const double chosen = automatic["settings"]["exposure"].get<double>();
    CHECK(chosen > 0.0);
    const json darker = bake_ok(dir, kCornellBox, dir / "dark", concat(kFast, {"--exposure", "-3"}));
    CHECK(darker["settings"]["exposure"].get<double>() == 0.125);
    const json brighter = bake_ok(dir, kCornellBox, dir / "bright", concat(kFast, {"--exposure", "2"}));
    CHECK(brighter["settings"]["exposure"].get<double>() == 4.0);
    // The same radiance, brighter pixels: the centre of the back wall.
    const float dark = centre(read_image(dir / "dark" / "render.png"), 0);
    const float bright = centre(read_image(dir / "bright" / "render.png"), 0);
    CHECK(bright > dark);
    // The linear image does not depend on the exposure: bit for bit the same.
    const ImageComparison same = compare_images(read_image(dir / "dark" / "render.exr"), read_image(dir / "bright" / "render.exr"));
    INFO(same.message);
    CHECK(same.same);
}

TEST_CASE("the progress option reports progress in a log, a line at a time, through every stage with the bake's time left", "[cli][view][eta]") {
    TempDir dir;
    // Draft: refinement and the final gather in about a second. (Not --hemicube 32 under the
    // default: its noisy solve refines to 67k elements, and their gather took 40 s.)
    const std::vector<std::string> quick = {"--quality", "draft", "--image-width", "64"};
    const RunResult r = run_hemirad(dir, concat(bake_args(kCornellBox, dir / "out", quick), {"--progress"}));
    INFO(r.err);
    REQUIRE(r.code == 0);
    CHECK(r.err.find("\r") == std::string::npos);  // not a terminal: no line redrawn in place
    // Every stage has its line (its first and its last at least), with its own progress.
    for (const char* stage : {"load", "mesh", "engines", "solve", "refine", "gather", "output"}) {
        INFO("stage " << stage);
        CHECK(r.err.find(std::string("hemirad: ") + stage + " ") != std::string::npos);
        CHECK(r.err.find(std::string("hemirad: ") + stage + " 100%") != std::string::npos);
    }
    CHECK(r.err.find("form-factor rows 206 / 206") != std::string::npos);
    CHECK(r.err.find(": re-gather") != std::string::npos);
    CHECK(r.err.find(" vertices") != std::string::npos);
    CHECK(r.err.find("output   0%  weld") != std::string::npos);
    CHECK(r.err.find("baked.gltf") != std::string::npos);
    // The bake's time left once the mesh's counts are known; unknown before.
    CHECK(r.err.find("load   0%  cornell_box.gltf  0.0 s  left ?") != std::string::npos);
    CHECK(r.err.find("hemirad: solve   0%  0.0 s  left ~") != std::string::npos);
    // report.json: a prediction and a measurement for every stage that ran, in order, and
    // the totals; the prediction made at 10% of the bake.
    const json report = read_json(dir / "out" / "report.json");
    const json& estimate = report.at("estimate");
    std::vector<std::string> names;
    double measured = 0.0, predicted = 0.0;
    for (const json& stage : estimate.at("stages")) {
        names.push_back(stage.at("name").get<std::string>());
        INFO("stage " << names.back());
        CHECK(stage.at("predicted_s").get<double>() >= 0.0);
        CHECK(stage.at("refit_s").get<double>() >= 0.0);
        CHECK(stage.at("measured_s").get<double>() >= 0.0);
        measured += stage.at("measured_s").get<double>();
        predicted += stage.at("predicted_s").get<double>();
    }
    CHECK(names == std::vector<std::string>{"load", "mesh", "engines", "solve", "refine", "gather", "output"});
    CHECK(estimate.at("total_predicted_s").get<double>() == Approx(predicted));
    // The stages follow one another: their sum is the bake's time but for what runs before the
    // first (the plan) and after the last (this report).
    CHECK(measured <= estimate.at("total_measured_s").get<double>());
    CHECK(estimate.at("total_measured_s").get<double>() <= report.at("timings_s").at("total").get<double>() + 1e-3);
    const json& at = estimate.at("at_10_percent");
    CHECK(at.at("predicted_total_s").get<double>() > 0.0);
    CHECK(at.at("ratio").get<double>() == Approx(at.at("predicted_total_s").get<double>() /
                                                 estimate.at("total_measured_s").get<double>()));
    // Without --progress a log gets none.
    const RunResult quiet = run_hemirad(dir, bake_args(kCornellBox, dir / "quiet", quick));
    CHECK(quiet.err.find("form-factor rows ") == std::string::npos);
    CHECK(quiet.err.find("re-gather") == std::string::npos);
    CHECK(quiet.err.find("left ~") == std::string::npos);
}

TEST_CASE("the progress line of a progressive solve with point lights: the lights' hemicubes, then passes of an expected total", "[cli][view][eta]") {
    TempDir dir;
    const RunResult r = run_hemirad(dir, {"bake", kClosedRoom.string(), "-o", (dir / "out").string(), "--quality", "draft",
                                          "--solver", "progressive", "--sun", "30,40,2000", "--image-width", "64",
                                          "--progress"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    CHECK(r.err.find("hemirad: solve ") != std::string::npos);
    CHECK(r.err.find("pass ") != std::string::npos);
    const json report = read_json(dir / "out" / "report.json");
    bool solve = false;
    for (const json& stage : report.at("estimate").at("stages")) solve = solve || stage.at("name") == "solve";
    CHECK(solve);
}

TEST_CASE("bad input with --progress is still one line on stderr", "[cli][view][eta]") {
    TempDir dir;
    write_text(dir / "bad.gltf", "{ not json");
    const RunResult r = run_hemirad(dir, {"bake", (dir / "bad.gltf").string(), "-o", (dir / "out").string(), "--progress"});
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK(r.err.find("left") == std::string::npos);
}

TEST_CASE("view options that cannot be used are refused with one line", "[cli][view]") {
    TempDir dir;
    const auto refused = [&](const std::vector<std::string>& args, const std::string& problem) {
        const RunResult r = run_hemirad(dir, concat(bake_args(kCornellBox, dir / "out"), args));
        INFO(r.err);
        CHECK(r.code == 2);
        CHECK(r.err.find(problem) != std::string::npos);
        CHECK(!fs::exists(dir / "out"));
    };
    refused({"--look-from", "0,0,1"}, "--look-from needs --look-at");
    refused({"--look-at", "0,0,1"}, "--look-at needs --look-from");
    refused({"--look-from", "0,0", "--look-at", "0,0,1"}, "--look-from '0,0': expected X,Y,Z");
    refused({"--look-from", "0,0,1,2", "--look-at", "0,0,1"}, "expected X,Y,Z");
    refused({"--look-from", "0,nan,1", "--look-at", "0,0,1"}, "expected X,Y,Z");
    refused({"--look-from", "0,0,1", "--look-at", "0,0,1"}, "two different points");
    refused({"--look-from", "0,0,1", "--look-at", "0,0,0", "--camera", "cornell"}, "give one");
    refused({"--exposure", "100"}, "--exposure");
    refused({"--fov", "0"}, "--fov");
}
