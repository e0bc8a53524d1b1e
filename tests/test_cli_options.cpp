// The command line's number options, parsed in process by cli::run (the executable's main): every
// one refuses NaN, Inf and values out of range with exit 2 and one line naming it, before any
// work. In process because there are many cases and starting the executable takes a second here
// (never a bake in process: it installs the CLI's signal handlers).
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <catch2/catch.hpp>

#include "cli/app.h"

namespace {

namespace fs = std::filesystem;

struct Parsed {
    int code = -1;
    std::string err;
};

// cli::run on `args`, its stderr captured.
Parsed run_cli(std::vector<std::string> args) {
    args.insert(args.begin(), "hemirad");
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    std::ostringstream captured;
    std::streambuf* const saved = std::cerr.rdbuf(captured.rdbuf());
    Parsed p;
    try {
        p.code = hemirad::cli::run(int(argv.size()), argv.data());
    } catch (...) {
        std::cerr.rdbuf(saved);
        throw;
    }
    std::cerr.rdbuf(saved);
    p.err = captured.str();
    return p;
}

// Exit 2, one line naming `option`, and nothing at `out`.
void check_refused(const std::vector<std::string>& args, const std::string& option, const fs::path& out) {
    const Parsed p = run_cli(args);
    INFO("stderr: [" << p.err << "]");
    CHECK(p.code == 2);
    CHECK(std::count(p.err.begin(), p.err.end(), '\n') == 1);
    CHECK(p.err.rfind("hemirad: " + option + ": ", 0) == 0);
    CHECK(!fs::exists(out));
}

const std::string kScene = std::string(HEMIRAD_SOURCE_DIR) + "/scenes/closed_room.gltf";

}  // namespace

TEST_CASE("options: every number option refuses NaN, Inf, other spellings and values out of range", "[cli][hostile]") {
    std::random_device rd;
    const fs::path out = fs::temp_directory_path() / ("hemirad-options-" + std::to_string(getpid()) + "-" +
                                                      std::to_string(rd()));
    const auto bake = [&](const std::string& option, const std::string& value) {
        return std::vector<std::string>{"bake", kScene, "-o", out.string(), "--quiet", option, value};
    };
    const std::vector<std::string> bake_numbers = {
        "--hemicube", "--patch-size",       "--element-size", "--threshold",     "--max-passes",
        "--batch",    "--seed",             "--contrast",     "--refine-levels", "--checkpoint-every",
        "--verify-every", "--preview-every", "--image-width"};
    // Not finite, or not a number at all: strtod and strtoll take most of these, and CLI11's
    // range checks let NaN through (every comparison with it is false).
    for (const std::string& option : bake_numbers) {
        for (const std::string value : {"nan", "-nan", "NAN(1)", "inf", "-inf", "Infinity", "1e400", "", "x", "1 2"}) {
            INFO(option << " '" << value << "'");
            check_refused(bake(option, value), option, out);
        }
    }
    // Finite but out of range, or a spelling that hides the number (hex, octal, a unit, a comma).
    const std::vector<std::pair<std::string, std::string>> out_of_range = {
        {"--hemicube", "7"},          {"--hemicube", "4098"},       {"--hemicube", "64.0"},
        {"--patch-size", "0"},        {"--patch-size", "-1"},       {"--patch-size", "0.5m"},
        {"--patch-size", "1,5"},      {"--patch-size", "1e31"},     {"--element-size", "-0.1"},
        {"--threshold", "-0.001"},    {"--threshold", "1.5"},       {"--threshold", "1e-400"},
        {"--threshold", "0"},
        {"--max-passes", "-1"},       {"--max-passes", "1e3"},      {"--max-passes", "99999999999999999999"},
        {"--batch", "0"},             {"--batch", "257"},           {"--batch", "0x10"},
        {"--seed", "-1"},             {"--seed", "18446744073709551616"}, {"--seed", "1.5"},
        {"--contrast", "0"},          {"--contrast", "2"},          {"--refine-levels", "7"},
        {"--checkpoint-every", "0"},  {"--verify-every", "0"},      {"--preview-every", "-1"},
        {"--image-width", "15"},      {"--image-width", "16385"},
        {"--gather", "-1"},           {"--gather", "7"},            {"--gather", "6"},
        {"--gather", "4098"},         {"--gather-passes", "0"},     {"--gather-passes", "9"},
        {"--gather-refine", "-1"},    {"--gather-refine", "9"},     {"--gather-contrast", "0"},
        {"--gather-contrast", "1.5"}, {"--gather-contrast", "nan"}, {"--gather-points", "-1"},
        {"--gather-points", "1e3"},
    };
    for (const auto& [option, value] : out_of_range) {
        INFO(option << " " << value);
        check_refused(bake(option, value), option, out);
    }
    // bench's numbers, before its --json file is written.
    const fs::path report = out.string() + ".json";
    for (const std::string option :
         {"--hemicube", "--shots", "--repeats", "--batch", "--patch-size", "--element-size", "--seed"}) {
        for (const std::string value : {"nan", "inf", "-1"}) {
            INFO(option << " " << value);
            check_refused({"bench", "procedural:100", option, value, "--json", report.string()}, option, report);
        }
    }
    check_refused({"bench", "procedural:100", "--hemicube", "32,nan", "--json", report.string()}, "--hemicube", report);
    // Finite sizes the mesher cannot take, before anything is measured (they were internal errors).
    // (The same for bake: "hostile input: a NaN option is refused before any work", test_cli.cpp.)
    const std::vector<std::string> bench = {"bench", "procedural:100", "--engines", "ref", "--no-calibrate", "--json",
                                            report.string()};
    std::vector<std::string> tiny = bench, inverted = bench;
    tiny.insert(tiny.end(), {"--element-size", "1e-300"});
    inverted.insert(inverted.end(), {"--patch-size", "0.1", "--element-size", "1"});
    const Parsed p = run_cli(tiny);
    CHECK(p.code == 2);
    CHECK(p.err.find("procedural:100 with --element-size 1e-300: inf elements") != std::string::npos);
    const Parsed q = run_cli(inverted);
    CHECK(q.code == 2);
    CHECK(q.err.find("--element-size 1: elements of 1 are larger than the patches (0.1)") != std::string::npos);
    CHECK(!fs::exists(report));
}
