// Automatic checkpoints and stage checkpoints (bake/stage_checkpoint.h): a bake killed while
// refining, gathering or writing is resumed by the same command with the bytes of a bake never
// killed; what is not its own, or is damaged, is ignored; nothing is left once the bake is done.
#include <stdlib.h>
#include <sys/stat.h>

#include <chrono>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "bake/bake.h"
#include "bake/checkpoint.h"
#include "bake/stage_checkpoint.h"
#include "cli_support.h"

namespace hemirad::test {

namespace {

// A bake of the closed room on the reference engine (no OpenCL program cache in the test's cache
// folder), with refinement and a final gather, and not --quiet: the notes say what it resumed.
std::vector<std::string> room_bake(const fs::path& out, const std::vector<std::string>& extra = {}) {
    return concat(bake_args(kClosedRoom, out,
                            {"--hemicube", "32", "--patch-size", "1.0", "--element-size", "0.5", "--max-passes", "200",
                             "--image-width", "64", "--device", "ref", "--gather", "16"}),
                  extra);
}

// The environment of a bake whose automatic checkpoint is on whatever its expected time,
// kept in `cache`/checkpoints; `fault`: HEMIRAD_FAULT's value, or none.
std::string automatic(const fs::path& cache, const std::string& fault = "") {
    return "HEMIRAD_CACHE_DIR=" + shell_quote(cache.string()) + " HEMIRAD_CHECKPOINT_ABOVE=0 " +
           (fault.empty() ? "" : "HEMIRAD_FAULT=" + fault + " ");
}

// The checkpoint files in `cache`/checkpoints.
std::vector<fs::path> checkpoints_in(const fs::path& cache) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (fs::directory_iterator it(cache / "checkpoints", ec), end; !ec && it != end; it.increment(ec))
        files.push_back(it->path());
    return files;
}

// What must be the same in a resumed bake's report and an uninterrupted one's.
void check_same_numbers(const json& resumed, const json& full) {
    for (const char* key : {"passes", "converged", "error", "energy", "counts", "meshes", "effects", "settings"})
        CHECK(resumed.at(key) == full.at(key));
}

}  // namespace

TEST_CASE("auto checkpoint: a bake killed while refining, gathering or writing resumes with an uninterrupted bake's bytes",
          "[cli][checkpoint]") {
    TempDir dir;
    const fs::path cache = dir / "cache";
    // The independent reference: the same bake, never killed, with no checkpoint at all.
    const RunResult plain = run_hemirad(dir, room_bake(dir / "full", {"--no-checkpoint"}), automatic(cache));
    INFO("stderr: " << plain.err);
    REQUIRE(plain.code == 0);
    CHECK(checkpoints_in(cache).empty());  // --no-checkpoint: none written, even for a long bake
    const json full = read_json(dir / "full" / "report.json");
    CHECK_FALSE(full.contains("checkpoint"));
    REQUIRE(full.at("counts").at("gather_points").get<long>() > 0);
    REQUIRE(full.at("counts").at("elements").get<long>() > full.at("counts").at("elements_before_refinement").get<long>());
    const std::string full_bin = read_text(dir / "full" / "baked.bin");

    // Killed as a stage begins: the rerun says it resumes from the stage before, and does not run
    // that stage again (a fault there would kill it).
    struct Case {
        const char* killed_at;
        const char* resumes_from;
        const char* skipped;
    };
    for (const Case& c : {Case{"refine", "solved", "solve"}, Case{"gather", "refined", "refine"},
                          Case{"output", "gathered", "gather"}}) {
        INFO("killed at " << c.killed_at);
        const fs::path out = dir / (std::string("out_") + c.killed_at);
        const RunResult killed = run_hemirad(dir, room_bake(out), automatic(cache, std::string("stage:") + c.killed_at));
        CHECK(killed.code == 128 + 9);  // SIGKILL
        CHECK_FALSE(fs::exists(out / "report.json"));
        CHECK_FALSE(fs::exists(out / "baked.bin"));
        REQUIRE(checkpoints_in(cache).size() == 1);

        const RunResult rerun = run_hemirad(dir, room_bake(out), automatic(cache, std::string("stage:") + c.skipped));
        INFO("stderr: " << rerun.err);
        REQUIRE(rerun.code == 0);
        CHECK(rerun.err.find("resuming from the checkpoint of") != std::string::npos);
        const json resumed = read_json(out / "report.json");
        CHECK(resumed.at("resumed").at("from") == c.resumes_from);
        CHECK(resumed.at("checkpoint").at("automatic") == true);
        CHECK(resumed.at("resumed").at("file") == resumed.at("checkpoint").at("file"));
        CHECK(read_text(out / "baked.bin") == full_bin);
        check_same_numbers(resumed, full);
        CHECK(resumed.at("warnings") == full.at("warnings"));
        // Done: the checkpoint is gone, and so is the killed bake's staging folder.
        CHECK(checkpoints_in(cache).empty());
        for (const auto& e : fs::directory_iterator(out))
            CHECK(e.path().filename().string().rfind(".hemirad-tmp-", 0) != 0);
    }
}

TEST_CASE("auto checkpoint: another bake's, or a damaged one, is not resumed and short bakes keep none", "[cli][checkpoint]") {
    TempDir dir;
    const fs::path cache = dir / "cache";
    REQUIRE(run_hemirad(dir, room_bake(dir / "full", {"--no-checkpoint"}), automatic(cache)).code == 0);
    const std::string full_bin = read_text(dir / "full" / "baked.bin");
    const auto killed_at_refine = [&](const std::vector<std::string>& extra = {}) {
        REQUIRE(run_hemirad(dir, room_bake(dir / "killed", extra), automatic(cache, "stage:refine")).code == 137);
        REQUIRE(checkpoints_in(cache).size() == 1);
        return checkpoints_in(cache).front();
    };

    SECTION("a setting that changes the solve: another file, not resumed, left for its own bake") {
        const fs::path other = killed_at_refine();
        const RunResult r = run_hemirad(dir, room_bake(dir / "out", {"--seed", "7"}), automatic(cache));
        INFO("stderr: " << r.err);
        REQUIRE(r.code == 0);
        CHECK(r.err.find("resuming") == std::string::npos);
        CHECK_FALSE(read_json(dir / "out" / "report.json").contains("resumed"));
        CHECK(checkpoints_in(cache) == std::vector<fs::path>{other});
    }
    SECTION("a refinement setting: the solved light is resumed, the refined light is not (a warning)") {
        // The reference: --contrast 0.9, never killed.
        REQUIRE(run_hemirad(dir, room_bake(dir / "full09", {"--no-checkpoint", "--contrast", "0.9"}), automatic(cache))
                    .code == 0);
        const std::string full09 = read_text(dir / "full09" / "baked.bin");
        REQUIRE(full09 != full_bin);
        killed_at_refine();
        const RunResult solved = run_hemirad(dir, room_bake(dir / "out", {"--contrast", "0.9"}), automatic(cache));
        INFO("stderr: " << solved.err);
        REQUIRE(solved.code == 0);
        CHECK(read_json(dir / "out" / "report.json").at("resumed").at("from") == "solved");
        CHECK(read_text(dir / "out" / "baked.bin") == full09);

        REQUIRE(run_hemirad(dir, room_bake(dir / "killed"), automatic(cache, "stage:gather")).code == 137);
        REQUIRE(checkpoints_in(cache).size() == 1);
        const RunResult refined = run_hemirad(dir, room_bake(dir / "out", {"--contrast", "0.9"}), automatic(cache));
        INFO("stderr: " << refined.err);
        REQUIRE(refined.code == 0);
        CHECK(refined.err.find("resuming") == std::string::npos);
        const json report = read_json(dir / "out" / "report.json");
        CHECK_FALSE(report.contains("resumed"));
        CHECK(report.at("warnings").dump().find("ignored the automatic checkpoint") != std::string::npos);
        CHECK(read_text(dir / "out" / "baked.bin") == full09);
        CHECK(checkpoints_in(cache).empty());
    }
    SECTION("damaged: one byte flipped, or cut short, is ignored with a warning and the bake completes") {
        for (const bool cut : {false, true}) {
            INFO((cut ? "cut short" : "a byte flipped"));
            const fs::path file = killed_at_refine();
            std::string bytes = read_text(file);
            if (cut)
                bytes.resize(bytes.size() / 3);
            else
                bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x04);
            write_text(file, bytes);
            const RunResult r = run_hemirad(dir, room_bake(dir / "killed"), automatic(cache));
            INFO("stderr: " << r.err);
            REQUIRE(r.code == 0);
            const json report = read_json(dir / "killed" / "report.json");
            CHECK_FALSE(report.contains("resumed"));
            CHECK(report.at("warnings").dump().find("ignored the automatic checkpoint") != std::string::npos);
            CHECK(r.err.find("warning: ignored the automatic checkpoint") != std::string::npos);
            CHECK(read_text(dir / "killed" / "baked.bin") == full_bin);
            CHECK(checkpoints_in(cache).empty());
        }
    }
    SECTION("a bake expected to take less than a minute keeps none, unless --checkpoint asks") {
        const std::string cache_only = "HEMIRAD_CACHE_DIR=" + shell_quote(cache.string()) + " ";
        const RunResult r = run_hemirad(dir, room_bake(dir / "short"),
                                        "env -u HEMIRAD_CHECKPOINT_ABOVE " + cache_only + "HEMIRAD_FAULT=stage:refine ");
        CHECK(r.code == 137);
        CHECK(checkpoints_in(cache).empty());
        const fs::path asked = dir / "asked.ckpt";
        REQUIRE(run_hemirad(dir, room_bake(dir / "short", {"--checkpoint", asked.string()}),
                            "env -u HEMIRAD_CHECKPOINT_ABOVE " + cache_only + "HEMIRAD_FAULT=stage:refine ")
                    .code == 137);
        CHECK(fs::is_regular_file(asked));
        CHECK(checkpoints_in(cache).empty());
        // --checkpoint FILE is the user's: resumed with --resume, and kept after the bake.
        const RunResult resumed = run_hemirad(dir, room_bake(dir / "short", {"--resume", asked.string()}), cache_only);
        INFO("stderr: " << resumed.err);
        REQUIRE(resumed.code == 0);
        CHECK(read_json(dir / "short" / "report.json").at("resumed").at("from") == "solved");
        CHECK(read_text(dir / "short" / "baked.bin") == full_bin);
        CHECK(fs::is_regular_file(asked));
    }
    SECTION("--no-checkpoint with --checkpoint is refused") {
        const RunResult r =
            run_hemirad(dir, room_bake(dir / "both", {"--no-checkpoint", "--checkpoint", (dir / "x").string()}));
        CHECK(r.code == 2);
        CHECK_FALSE(fs::exists(dir / "both"));
    }
}

TEST_CASE("a bake stopped by Ctrl-C while solving keeps the solver's state, which resumes to the same bytes",
          "[cli][checkpoint]") {
    TempDir dir;
    // A solve of some seconds on the reference engine (3000 passes), no gather.
    const std::vector<std::string> settings = {"--hemicube", "64", "--patch-size", "0.5", "--element-size", "0.25",
                                               "--threshold", "1e-7", "--max-passes", "3000", "--solver",
                                               "progressive", "--gather", "0", "--image-width", "32", "--device", "ref"};
    const json full = bake_ok(dir, kClosedRoom, dir / "full", concat(settings, {"--quiet"}));
    REQUIRE(full.at("passes") == 3000);
    const fs::path ck = dir / "ck";
    // --checkpoint-every past the bake's end: only the stop writes the solver's state. The signal
    // goes half a second after the solve has begun ("form factors on" is said as it begins).
    std::string script = "env --default-signal=INT " + shell_quote(HEMIRAD_EXE);
    for (const std::string& a :
         bake_args(kClosedRoom, dir / "out", concat(settings, {"--checkpoint", ck.string(), "--checkpoint-every", "1000000"})))
        script += " " + shell_quote(a);
    script += " 2>err.txt & pid=$!; i=0; while ! grep -q 'form factors' err.txt 2>/dev/null && [ $i -lt 600 ]; do "
              "sleep 0.05; i=$((i+1)); done; sleep 0.5; kill -INT $pid; wait $pid; echo code=$?";
    const RunResult r = run_shell(dir, script);
    INFO("stdout: " << r.out << " stderr: " << read_text(dir / "err.txt"));
    CHECK(r.out.find("code=130") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "out"));
    REQUIRE(fs::is_regular_file(ck));
    const json resumed = bake_ok(dir, kClosedRoom, dir / "out", concat(settings, {"--quiet", "--resume", ck.string()}));
    CHECK(resumed.at("resumed").at("from") == "solving");
    CHECK(resumed.at("resumed_from_pass").get<long>() > 0);
    CHECK(resumed.at("resumed_from_pass").get<long>() < 3000);
    CHECK(resumed.at("passes") == 3000);
    CHECK(resumed.at("energy") == full.at("energy"));
    CHECK(read_text(dir / "out" / "baked.bin") == read_text(dir / "full" / "baked.bin"));
}

TEST_CASE("auto checkpoint: on by default past a minute expected, in the cache folder named by the bake", "[checkpoint]") {
    TempDir dir;
    const std::string old_cache = getenv("HEMIRAD_CACHE_DIR") ? getenv("HEMIRAD_CACHE_DIR") : "";
    const std::string old_above = getenv("HEMIRAD_CHECKPOINT_ABOVE") ? getenv("HEMIRAD_CHECKPOINT_ABOVE") : "";
    setenv("HEMIRAD_CACHE_DIR", (dir / "cache").c_str(), 1);
    unsetenv("HEMIRAD_CHECKPOINT_ABOVE");
    bake::Options o;
    o.scene = kClosedRoom.string();
    o.output = (dir / "out").string();
    o.patch_size = 1.0;
    o.element_size = 0.5;
    o.device = "ref";
    const bake::Plan plan = bake::make_plan(o);
    scene::Scene scene = scene::load(o.scene);
    const bake::Setup setup = bake::set_up(plan, scene);
    const bake::Meshed meshed = bake::build_mesh(plan, setup, scene);
    bake::Progress progress;
    bake::Warnings warnings(progress);
    const auto planned = [&](double expected, bool no_checkpoint = false, const std::string& fingerprint = "a") {
        bake::Plan p = plan;
        p.o.no_checkpoint = no_checkpoint;
        bake::StageCheckpoints cp;
        cp.fingerprint = fingerprint;
        bake::plan_checkpoints(cp, p, setup, meshed, expected, warnings, progress);
        return cp;
    };
    CHECK_FALSE(planned(59.0).writing());
    const bake::StageCheckpoints on = planned(61.0);
    CHECK(on.automatic);
    CHECK(on.file.parent_path() == dir / "cache" / "checkpoints");
    CHECK(on.file.extension() == ".ckpt");
    CHECK(planned(61.0, false, "b").file != on.file);  // another bake, another file
    CHECK(planned(61.0, false, "a").file == on.file);
    CHECK_FALSE(planned(3600.0, /*no_checkpoint=*/true).writing());
    CHECK(warnings.all().empty());
    setenv("HEMIRAD_CACHE_DIR", "off", 1);
    CHECK_FALSE(planned(3600.0).writing());
    if (old_cache.empty()) unsetenv("HEMIRAD_CACHE_DIR");
    else setenv("HEMIRAD_CACHE_DIR", old_cache.c_str(), 1);
    if (!old_above.empty()) setenv("HEMIRAD_CHECKPOINT_ABOVE", old_above.c_str(), 1);
}

TEST_CASE("auto checkpoint: the cache folder is pruned by age and size, never this bake's or other files", "[checkpoint]") {
    TempDir dir;
    const fs::path folder = dir / "checkpoints";
    fs::create_directories(folder);
    const auto make = [&](const std::string& name, std::size_t bytes, double days_old) {
        const fs::path file = folder / name;
        write_text(file, std::string(bytes, 'x'));
        fs::last_write_time(file, fs::file_time_type::clock::now() -
                                      std::chrono::duration_cast<fs::file_time_type::duration>(
                                          std::chrono::duration<double>(days_old * 86400.0)));
        return file;
    };
    const fs::path mine = make("0000000000000001.ckpt", 5000, 30.0);        // this bake's: kept, however old
    const fs::path old = make("0000000000000002.ckpt", 10, 20.0);           // past 14 days
    const fs::path old_temp = make("0000000000000003.ckpt.tmp-99", 10, 20.0);
    const fs::path new_temp = make("0000000000000004.ckpt.tmp-98", 5000, 0.0);  // another bake writing it
    const fs::path newest = make("0000000000000005.ckpt", 600, 1.0);
    const fs::path older = make("0000000000000006.ckpt", 600, 2.0);          // over the cap with newest
    const fs::path other = make("notes.txt", 10, 100.0);                     // not a checkpoint: never touched
    CHECK(bake::prune_checkpoints(folder, mine, 14.0, 1000) == 3);
    CHECK(fs::exists(mine));
    CHECK_FALSE(fs::exists(old));
    CHECK_FALSE(fs::exists(old_temp));
    CHECK(fs::exists(new_temp));
    CHECK(fs::exists(newest));
    CHECK_FALSE(fs::exists(older));
    CHECK(fs::exists(other));
}

}  // namespace hemirad::test
