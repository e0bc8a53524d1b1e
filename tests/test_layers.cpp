// The modules' layers (docs/architecture.md): each module of src/ includes only itself and the
// modules below it, so that the bake library holds no benchmark, generator or argument parsing,
// and nothing below the bake knows of its stages. Read from the sources' #include lines.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>

namespace fs = std::filesystem;

namespace {

// Module → the modules it may include besides itself (the CMake targets follow the same order:
// hemirad_image holds image; hemirad_core holds core … dist, then hemirad_gen, hemirad_bake, hemirad_bench, hemirad_cli).
const std::map<std::string, std::set<std::string>>& allowed() {
    static const std::map<std::string, std::set<std::string>> rules = {
        {"core", {}},
        {"image", {"core"}},
        {"cl", {"core"}},
        {"scene", {"core", "image"}},
        {"mesh", {"core", "image", "scene"}},
        {"formfactor", {"core", "image", "cl", "scene", "mesh"}},
        {"output", {"core", "image", "scene", "mesh", "formfactor"}},
        {"solve", {"core", "image", "scene", "mesh", "formfactor", "output"}},
        {"dist", {"core", "image", "cl", "mesh", "formfactor"}},
        {"gen", {"core", "image", "scene"}},
        {"bake", {"core", "image", "cl", "scene", "mesh", "formfactor", "output", "solve", "dist"}},
        {"bench", {"core", "image", "cl", "scene", "mesh", "formfactor", "output", "solve", "dist", "gen", "bake"}},
        {"cli", {"core", "image", "cl", "scene", "mesh", "formfactor", "output", "solve", "dist", "gen", "bake", "bench"}},
    };
    return rules;
}

}  // namespace

TEST_CASE("layers: every module of src/ includes only the modules below it", "[layers]") {
    const fs::path src = fs::path(HEMIRAD_SOURCE_DIR) / "src";
    const std::regex include_line(R"(^\s*#\s*include\s*"([a-z_]+)/)");
    std::set<std::string> modules_seen;
    std::size_t includes = 0;
    for (const auto& dir : fs::directory_iterator(src)) {
        if (!dir.is_directory()) continue;
        const std::string module = dir.path().filename().string();
        INFO("module " << module);
        const auto rule = allowed().find(module);
        REQUIRE(rule != allowed().end());  // a new module gets its layer here and in docs/architecture.md
        modules_seen.insert(module);
        for (const auto& file : fs::directory_iterator(dir.path())) {
            std::ifstream in(file.path());
            std::string line;
            for (int number = 1; std::getline(in, line); ++number) {
                std::smatch m;
                if (!std::regex_search(line, m, include_line)) continue;
                ++includes;
                const std::string target = m[1];
                INFO(file.path().filename().string() << ":" << number << ": " << line);
                CHECK((target == module || rule->second.count(target) > 0));
            }
        }
    }
    CHECK(modules_seen.size() == allowed().size());
    CHECK(includes > 300);  // the walk read the sources (399 today)
}
