// The host stages' threads (core/parallel.h): every item once at any thread count, and a bake's
// bytes the same on one host thread and on more threads than the machine has cores.
#include <catch2/catch.hpp>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bake/bake.h"
#include "core/parallel.h"

using namespace hemirad;

namespace {

std::string file_bytes(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    REQUIRE(in);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST_CASE("host threads: for_each visits every item once, on as many threads as allowed", "[parallel]") {
    for (const int threads : {1, 2, 7}) {
        const parallel::ThreadLimit limit(threads);
        CHECK(parallel::threads() <= threads);
        std::vector<std::atomic<int>> seen(10007);
        for (auto& s : seen) s.store(0);
        parallel::for_each(seen.size(), 3, [&](std::size_t i) { seen[i].fetch_add(1); });
        int wrong = 0;
        for (const auto& s : seen) wrong += s.load() == 1 ? 0 : 1;
        CHECK(wrong == 0);
        // Ranges cover [0, count) once, each at least the grain but the last.
        std::vector<std::atomic<int>> covered(1000);
        for (auto& c : covered) c.store(0);
        parallel::for_ranges(covered.size(), 64, [&](std::size_t begin, std::size_t end) {
            CHECK(begin < end);
            for (std::size_t i = begin; i < end; ++i) covered[i].fetch_add(1);
        });
        wrong = 0;
        for (const auto& c : covered) wrong += c.load() == 1 ? 0 : 1;
        CHECK(wrong == 0);
    }
    parallel::for_each(0, 1, [](std::size_t) { FAIL("no items: no call"); });
}

TEST_CASE("host threads: a bake's bytes are the same on one host thread and on five", "[parallel][bake]") {
    // The curved objects: clusters drawn as faces by the gather, a sparse gather (a budget of 600
    // points of its vertices: seeds, levels, interpolation over nodes), contact lines, the
    // render's strips. Five threads on a two-core machine interleave at random.
    const std::filesystem::path root(HEMIRAD_SOURCE_DIR);
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hemirad-test-threads";
    std::filesystem::remove_all(dir);
    const auto bake_with = [&](int threads) {
        bake::Options o;
        o.scene = (root / "scenes/curved_objects.gltf").string();
        o.output = (dir / std::to_string(threads)).string();
        o.quality = "draft";
        o.gather = 32;
        o.gather_points = 600;
        o.threads = threads;
        o.quiet = true;
        o.no_checkpoint = true;
        bake::run(o);
        return o.output;
    };
    const std::filesystem::path one = bake_with(1), five = bake_with(5);
    std::ifstream in(five / "report.json");
    const nlohmann::json report = nlohmann::json::parse(in);
    CAPTURE(report["counts"]);
    CHECK(report.at("settings").at("threads").get<int>() <= 5);
    CHECK(report.at("counts").at("sparse_gather").at("points").get<long>() > 0);
    CHECK(file_bytes(one / "baked.bin") == file_bytes(five / "baked.bin"));
    CHECK(file_bytes(one / "render.png") == file_bytes(five / "render.png"));
    std::filesystem::remove_all(dir);
}
