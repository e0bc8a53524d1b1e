// The embedded kernel sources (cmake/EmbedKernels.cmake): hemicube.cl split by stage into files
// that the embedding inlines, with #line directives that name each line's real file and line, so
// that a device compiler's build log points at kernels/FILE:LINE. The mapping is checked line by
// line against the files in the source tree (no device needed); where there is an OpenCL device,
// build logs are checked to name the real place of errors put there on purpose.
#include <catch2/catch.hpp>
#include <cstddef>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "backends.h"
#include "cl/runtime.h"

using namespace hemirad;

namespace {

const std::string kSourceDir = HEMIRAD_SOURCE_DIR;

// Every kernel the host builds (each one program), and the stage files hemicube.cl includes.
const std::vector<std::string> kKernels = {"hemicube.cl", "parallel.cl", "calibrate.cl"};
const std::vector<std::string> kHemicubeParts = {
    "hemicube_types.h",      "hemicube_common.cl", "hemicube_setup.cl",  "hemicube_setup_lanes.cl",
    "hemicube_cull.cl",      "hemicube_scan.cl",   "hemicube_raster.cl", "hemicube_raster_records.cl"};

// The lines of `text`, a final newline ending the last (not starting an empty one).
std::vector<std::string> lines_of(std::string_view text) {
    std::vector<std::string> lines;
    std::size_t at = 0;
    while (at < text.size()) {
        const std::size_t end = text.find('\n', at);
        if (end == std::string_view::npos) {
            lines.emplace_back(text.substr(at));
            break;
        }
        lines.emplace_back(text.substr(at, end - at));
        at = end + 1;
    }
    return lines;
}

// The lines of a file of the source tree, `path` relative to its root ("kernels/x.cl").
const std::vector<std::string>& real_lines(const std::string& path) {
    static std::map<std::string, std::vector<std::string>> files;
    if (auto it = files.find(path); it != files.end()) return it->second;
    std::ifstream in(kSourceDir + "/" + path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot read " + kSourceDir + "/" + path);
    std::ostringstream text;
    text << in.rdbuf();
    return files.emplace(path, lines_of(text.str())).first->second;
}

// The 1-based line of kernels/`file` holding `needle` (exactly once in the file).
int line_holding(const std::string& file, const std::string& needle) {
    const std::vector<std::string>& lines = real_lines("kernels/" + file);
    int found = 0;
    for (std::size_t k = 0; k < lines.size(); ++k)
        if (lines[k].find(needle) != std::string::npos) {
            if (found != 0) throw std::runtime_error(needle + " twice in kernels/" + file);
            found = static_cast<int>(k) + 1;
        }
    if (found == 0) throw std::runtime_error(needle + " not in kernels/" + file);
    return found;
}

// A #line directive's line number and file name.
std::optional<std::pair<int, std::string>> line_directive(const std::string& line) {
    static const std::regex kLine(R"re(#line (\d+) "([^"]+)")re");
    std::smatch m;
    if (!std::regex_match(line, m, kLine)) return std::nullopt;
    return std::make_pair(std::stoi(m[1]), m[2].str());
}

// Where the embedded text of `kernel` puts each of its lines: checks every line that is no
// #line directive against the real file's line it is attributed to, and returns the lines of
// each file the text holds.
std::map<std::string, std::set<int>> check_mapping(const std::string& kernel) {
    const std::vector<std::string> embedded = lines_of(ocl::kernel_source(kernel));
    REQUIRE(!embedded.empty());
    REQUIRE(line_directive(embedded.front()) == std::make_pair(1, "kernels/" + kernel));
    std::map<std::string, std::set<int>> covered;
    std::string file;
    int line = 0;
    std::size_t checked = 0, wrong = 0;
    for (std::size_t k = 0; k < embedded.size(); ++k) {
        if (const auto directive = line_directive(embedded[k])) {
            line = directive->first;
            file = directive->second;
            continue;
        }
        const std::vector<std::string>& real = real_lines(file);
        // An include of a file already inlined becomes "// <the include> (inlined above)".
        const std::string& text = embedded[k];
        const bool in_range = line >= 1 && static_cast<std::size_t>(line) <= real.size();
        const bool same = in_range && (text == real[static_cast<std::size_t>(line) - 1] ||
                                       text == "// " + real[static_cast<std::size_t>(line) - 1] + " (inlined above)");
        if (!same && wrong++ < 5)
            FAIL_CHECK(kernel << " line " << k + 1 << ", attributed to " << file << ":" << line << ", is '" << text
                              << "' but the file has '"
                              << (in_range ? real[static_cast<std::size_t>(line) - 1] : "(no such line)") << "'");
        covered[file].insert(line);
        ++checked;
        ++line;
    }
    CAPTURE(kernel, checked);
    CHECK(wrong == 0);
    return covered;
}

// The build log of `source` with `options`, which must fail to build.
std::string failed_build_log(ocl::Context& ctx, const std::string& source, const std::string& options) {
    try {
        ctx.program(source, options);
    } catch (const ocl::BuildError& e) {
        return e.what();
    }
    FAIL("built with options '" << options << "', which should break it");
    return "";
}

}  // namespace

TEST_CASE("kernels: hemicube.cl is embedded whole, each stage file inlined once with #line directives",
          "[kernels]") {
    const std::string source(ocl::kernel_source("hemicube.cl"));
    for (const std::string& part : kHemicubeParts) {
        const std::string directive = "#line 1 \"kernels/" + part + "\"\n";
        CAPTURE(part);
        const std::size_t at = source.find(directive);
        REQUIRE(at != std::string::npos);
        CHECK(source.find(directive, at + 1) == std::string::npos);
        // No include of our own files is left for the device compiler to look for.
        CHECK(source.find("#include \"" + part + "\"") == std::string::npos);
    }
    // The stages follow one another in the pipeline's order, in one program.
    std::size_t previous = 0;
    for (const char* stage : {"hemicube_common.cl", "hemicube_setup.cl", "hemicube_setup_lanes.cl", "hemicube_cull.cl",
                              "hemicube_scan.cl", "hemicube_raster.cl", "hemicube_raster_records.cl"}) {
        const std::size_t at = source.find("#line 1 \"kernels/" + std::string(stage) + "\"");
        CAPTURE(stage);
        CHECK(at > previous);
        previous = at;
    }
    for (const char* kernel :
         {"void setup(", "void cull_clusters(", "void scan(", "void scatter(", "void raster(", "void raster_records(",
          "void floor_div_pairs(", "void layout("})
        CHECK(source.find(kernel) != std::string::npos);
    // The stage files are parts of hemicube.cl, not programs of their own.
    for (const std::string& part : kHemicubeParts) CHECK_THROWS_AS(ocl::kernel_source(part), std::out_of_range);
}

TEST_CASE("kernels: every embedded line is the line of the real file that its #line directive names",
          "[kernels]") {
    for (const std::string& kernel : kKernels) {
        const std::map<std::string, std::set<int>> covered = check_mapping(kernel);
        // And each file's every line is there, but the includes that were inlined in its place.
        for (const auto& [file, lines] : covered) {
            const std::vector<std::string>& real = real_lines(file);
            std::size_t missing = 0;
            for (std::size_t k = 0; k < real.size(); ++k) {
                if (lines.count(static_cast<int>(k) + 1) != 0) continue;
                const bool inlined_include = real[k].rfind("#include \"", 0) == 0;
                if (!inlined_include && missing++ < 5)
                    FAIL_CHECK(kernel << ": " << file << ":" << k + 1 << " is missing: '" << real[k] << "'");
            }
            CAPTURE(kernel, file);
            CHECK(missing == 0);
        }
    }
    const std::map<std::string, std::set<int>> hemicube = check_mapping("hemicube.cl");
    for (const std::string& part : kHemicubeParts) CHECK(hemicube.count("kernels/" + part) == 1);
}

TEST_CASE("opencl: a build log names the file and line a #line directive gives", "[opencl][kernels]") {
    const test::Backend& device = test::first_opencl();
    HEMIRAD_SKIP_ABSENT(device);
    ocl::Context* ctx = device.context();
    const std::string source =
        "__kernel void fine(__global int* a) { a[0] = 1; }\n"
        "#line 40 \"kernels/x.cl\"\n"
        "__kernel void broken(__global int* a) {\n"  // kernels/x.cl:40
        "    a[0] = not_declared_anywhere;\n"        // kernels/x.cl:41
        "}\n";
    const std::string log = failed_build_log(*ctx, source, "-cl-std=CL1.2");
    CAPTURE(log);
    CHECK(log.find("kernels/x.cl:41:") != std::string::npos);
}

TEST_CASE("opencl: an error in any stage of hemicube.cl is reported at its real file and line",
          "[opencl][kernels]") {
    const test::Backend& device = test::first_opencl();
    HEMIRAD_SKIP_ABSENT(device);
    ocl::Context* ctx = device.context();
    const std::string source(ocl::kernel_source("hemicube.cl"));
    // The engine's kind of options (knobs as -D, both setups), and one -D that turns a name into
    // a number: the compiler then stops at the name's definition, which the log must place.
    struct Break {
        std::string name, file, definition;
        bool lanes;
    };
    const std::vector<Break> breaks = {
        {"ClipPolygon", "hemicube_common.cl", "} ClipPolygon;", false},
        {"bin_records", "hemicube_setup.cl", "void bin_records(", false},
        {"snap_lanes", "hemicube_setup_lanes.cl", "llong snap_lanes(", true},
        {"group_hidden", "hemicube_cull.cl", "bool group_hidden(", true},
        {"scatter", "hemicube_scan.cl", "void scatter(", false},
        {"raster_tile", "hemicube_raster.cl", "bool raster_tile(", false},
        {"SumTable", "hemicube_raster_records.cl", "} SumTable;", true},
        {"layout", "hemicube.cl", "void layout(", false},
    };
    for (const Break& b : breaks) {
        const std::string options = std::string("-cl-std=CL1.2 -DHEMIRAD_TILE=16 -DHEMIRAD_WG=64 -DHEMIRAD_LANES=4 ") +
                                    "-DHEMIRAD_SETUP_LANES=" + (b.lanes ? "1" : "0") + " -D" + b.name + "=42";
        const std::string place = "kernels/" + b.file + ":" + std::to_string(line_holding(b.file, b.definition)) + ":";
        const std::string log = failed_build_log(*ctx, source, options);
        CAPTURE(options, place, log);
        CHECK(log.find(place) != std::string::npos);
    }
}
