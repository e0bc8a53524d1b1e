// The on-disk program binary cache: where it lives, what it refuses, and that a program loaded
// from it computes what one built from source does. Device tests run on the first OpenCL device
// (PoCL in CI) and warn and skip without one; each uses a cache directory of its own.
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cl/program_cache.h"
#include "cl/runtime.h"
#include "backends.h"
#include "cli_support.h"

using namespace hemirad;
using test::TempDir;
namespace fs = std::filesystem;

namespace {

// Sets (or with nullptr unsets) an environment variable for one scope. Each test case runs in a
// process of its own (catch_discover_tests), so no other test sees it.
class ScopedEnv {
public:
    ScopedEnv(const char* name, const char* value) : name_(name) {
        if (const char* old = std::getenv(name)) old_ = old;
        if (value)
            setenv(name, value, 1);
        else
            unsetenv(name);
    }
    ~ScopedEnv() {
        if (old_)
            setenv(name_.c_str(), old_->c_str(), 1);
        else
            unsetenv(name_.c_str());
    }
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

private:
    std::string name_;
    std::optional<std::string> old_;
};

// Small, so each build is quick; OFFSET comes from the options, so a program built with other
// options computes something else and serving it would show.
const std::string kSource = R"(
__kernel void affine(__global const float* in, __global float* out) {
    const size_t i = get_global_id(0);
    out[i] = in[i] * 3.0f + OFFSET;
}
)";

std::vector<float> run_affine(ocl::Context& ctx, const std::string& source, const std::string& options) {
    const std::vector<float> in = {0.0f, 1.0f, -2.5f, 1e6f, 0.125f};
    cl::Kernel kernel(ctx.program(source, options), "affine");
    cl::Buffer in_buffer(ctx.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, in.size() * sizeof(float),
                         const_cast<float*>(in.data()));
    cl::Buffer out_buffer(ctx.context(), CL_MEM_WRITE_ONLY, in.size() * sizeof(float));
    kernel.setArg(0, in_buffer);
    kernel.setArg(1, out_buffer);
    ctx.queue().enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(in.size()), cl::NullRange);
    std::vector<float> out(in.size());
    ctx.queue().enqueueReadBuffer(out_buffer, CL_TRUE, 0, out.size() * sizeof(float), out.data());
    return out;
}

std::vector<float> expected_affine(float offset) {
    std::vector<float> out;
    for (const float x : {0.0f, 1.0f, -2.5f, 1e6f, 0.125f}) out.push_back(x * 3.0f + offset);
    return out;
}

std::vector<fs::path> files_in(const fs::path& dir) {
    std::vector<fs::path> out;
    std::error_code ec;
    if (fs::exists(dir, ec))
        for (const auto& entry : fs::recursive_directory_iterator(dir)) out.push_back(entry.path());
    return out;
}

std::string read_bytes(const fs::path& file) {
    return test::read_text(file);
}

void write_bytes(const fs::path& file, const std::string& bytes) {
    std::ofstream out(file, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    REQUIRE(out.good());
}

const std::string kOptions = "-cl-std=CL1.2 -DOFFSET=1.0f";

}  // namespace

TEST_CASE("opencl: the program cache directory comes from HEMIRAD_CACHE_DIR, XDG_CACHE_HOME or HOME",
          "[opencl][cache]") {
    {
        ScopedEnv dir("HEMIRAD_CACHE_DIR", "/some/where");
        ScopedEnv xdg("XDG_CACHE_HOME", "/xdg");
        CHECK(ocl::program_cache_directory() == fs::path("/some/where"));
    }
    {
        ScopedEnv dir("HEMIRAD_CACHE_DIR", "off");
        ScopedEnv xdg("XDG_CACHE_HOME", "/xdg");
        CHECK(!ocl::program_cache_directory());
    }
    {
        ScopedEnv dir("HEMIRAD_CACHE_DIR", "");  // empty is unset
        ScopedEnv xdg("XDG_CACHE_HOME", "/xdg");
        CHECK(ocl::program_cache_directory() == fs::path("/xdg/hemirad"));
        CHECK(ocl::program_cache_directory("gpu") == fs::path("/xdg/hemirad"));
        CHECK(!ocl::program_cache_directory("cpu"));  // PoCL's own cache, unless asked for
    }
    {
        ScopedEnv dir("HEMIRAD_CACHE_DIR", "/asked/for");
        CHECK(ocl::program_cache_directory("cpu") == fs::path("/asked/for"));
    }
    {
        ScopedEnv dir("HEMIRAD_CACHE_DIR", nullptr);
        ScopedEnv home("HOME", "/home/someone");
        ScopedEnv xdg("XDG_CACHE_HOME", "relative");  // the XDG spec says to ignore it
        CHECK(ocl::program_cache_directory() == fs::path("/home/someone/.cache/hemirad"));
        ScopedEnv no_xdg("XDG_CACHE_HOME", nullptr);
        CHECK(ocl::program_cache_directory() == fs::path("/home/someone/.cache/hemirad"));
        ScopedEnv no_home("HOME", nullptr);
        CHECK(!ocl::program_cache_directory());
    }
}

TEST_CASE("opencl: the program cache returns exactly what was stored and refuses damaged entries", "[opencl][cache]") {
    const TempDir tmp;
    const ocl::ProgramCache cache(tmp / "cache");
    const std::string key = "device A\noptions: -DX=1\nsource:\nkernel text";
    std::vector<unsigned char> binary(5000);
    std::mt19937 random(7);
    for (auto& b : binary) b = static_cast<unsigned char>(random());

    CHECK(!cache.load(key));  // nothing yet (and no directory: created by the first store)
    REQUIRE(cache.store(key, binary));
    CHECK(cache.load(key) == binary);
    CHECK(!cache.load(key + " "));  // another key: another file, absent
    const fs::path entry = cache.entry_path(key);
    const std::string good = read_bytes(entry);

    SECTION("truncated") {
        for (const std::size_t keep : {std::size_t{0}, std::size_t{7}, std::size_t{20}, good.size() - 1}) {
            write_bytes(entry, good.substr(0, keep));
            CAPTURE(keep);
            CHECK(!cache.load(key));
        }
    }
    SECTION("a byte changed anywhere: the magic, a size, the key or the binary") {
        for (const std::size_t at :
             {std::size_t{3}, std::size_t{9}, std::size_t{17}, std::size_t{40}, good.size() - 1}) {
            std::string bad = good;
            bad[at] = static_cast<char>(bad[at] ^ 0x20);
            write_bytes(entry, bad);
            CAPTURE(at);
            CHECK(!cache.load(key));
        }
    }
    SECTION("bytes appended") {
        write_bytes(entry, good + "x");
        CHECK(!cache.load(key));
    }
    SECTION("an entry written for another key under the same file name") {
        const ocl::ProgramCache other(tmp / "other");
        REQUIRE(other.store("another key", binary));
        write_bytes(entry, read_bytes(other.entry_path("another key")));
        CHECK(!cache.load(key));
    }
    SECTION("a directory where the entry belongs") {
        fs::remove(entry);
        fs::create_directory(entry);
        CHECK(!cache.load(key));
        CHECK(!cache.store(key, binary));  // the rename cannot replace it: no error, no entry
    }
    SECTION("rewritten after damage") {
        write_bytes(entry, good.substr(0, 100));
        REQUIRE(cache.store(key, binary));
        CHECK(cache.load(key) == binary);
    }
    // No temporary files are left beside the entries.
    for (const fs::path& file : files_in(tmp / "cache")) CHECK(file.string().find(".tmp-") == std::string::npos);
}

TEST_CASE("opencl: the program cache skips a directory it cannot create, and a reader never sees half an entry",
          "[opencl][cache]") {
    const TempDir tmp;
    write_bytes(tmp / "a file", "not a directory");
    const ocl::ProgramCache blocked(tmp / "a file" / "cache");
    CHECK(!blocked.store("key", {1, 2, 3}));
    CHECK(!blocked.load("key"));
    CHECK(!ocl::ProgramCache(std::nullopt).store("key", {1, 2, 3}));

    // Two writers replacing one entry with binaries of different sizes while a reader loads it.
    const ocl::ProgramCache cache(tmp / "cache");
    const std::vector<unsigned char> small(1000, 1), large(400000, 2);
    REQUIRE(cache.store("key", small));
    int wrong = 0;
    {
        std::thread a([&] {
            for (int i = 0; i < 40; ++i) cache.store("key", large);
        });
        std::thread b([&] {
            for (int i = 0; i < 40; ++i) cache.store("key", small);
        });
        for (int i = 0; i < 200; ++i) {
            const auto got = cache.load("key");
            if (!got || (*got != small && *got != large)) ++wrong;
        }
        a.join();
        b.join();
    }
    CHECK(wrong == 0);
    CHECK(files_in(tmp / "cache").size() == 1);
}

TEST_CASE("opencl: a second context loads its program from the disk cache and computes the same", "[opencl][cache]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const ocl::DeviceInfo* const device = &test::first_opencl().context()->info();
    const TempDir tmp;
    std::vector<float> built, loaded;
    {
        ocl::Context first(*device, tmp.path());
        built = run_affine(first, kSource, kOptions);
        CHECK(first.program_counts().built == 1);
        CHECK(first.program_counts().loaded == 0);
        CHECK(first.program_counts().stored == 1);
        CHECK(fs::is_regular_file(first.program_cache().entry_path(first.program_key(kSource, kOptions))));
        run_affine(first, kSource, kOptions);  // the context's own cache: not built or loaded again
        CHECK(first.program_counts().built == 1);
        CHECK(first.program_counts().loaded == 0);
    }
    {
        ocl::Context second(*device, tmp.path());
        loaded = run_affine(second, kSource, kOptions);
        CHECK(second.program_counts().built == 0);
        CHECK(second.program_counts().loaded == 1);
        CHECK(second.program_counts().stored == 0);
    }
    CHECK(built == expected_affine(1.0f));
    CHECK(loaded == built);
}

TEST_CASE("opencl: a damaged or refused program cache entry is built from source again and rewritten",
          "[opencl][cache]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const ocl::DeviceInfo* const device = &test::first_opencl().context()->info();
    const TempDir tmp;
    fs::path entry;
    {
        ocl::Context first(*device, tmp.path());
        run_affine(first, kSource, kOptions);
        entry = first.program_cache().entry_path(first.program_key(kSource, kOptions));
    }
    const std::string good = read_bytes(entry);
    int rejected = 0;
    SECTION("truncated: refused by its size before the driver sees it (PoCL aborts on a cut binary)") {
        write_bytes(entry, good.substr(0, good.size() / 2));
    }
    SECTION("a byte flipped in the binary: refused by its checksum") {
        std::string bad = good;
        bad[bad.size() - 10] = static_cast<char>(bad[bad.size() - 10] ^ 1);
        write_bytes(entry, bad);
    }
    SECTION("a whole entry whose binary the driver refuses") {
        ocl::Context probe(*device, std::nullopt);
        const std::string key = probe.program_key(kSource, kOptions);
        std::vector<unsigned char> garbage(4096);
        std::mt19937 random(11);
        for (auto& b : garbage) b = static_cast<unsigned char>(random());
        REQUIRE(ocl::ProgramCache(tmp.path()).store(key, garbage));
        rejected = 1;
    }
    ocl::Context second(*device, tmp.path());
    CHECK(run_affine(second, kSource, kOptions) == expected_affine(1.0f));
    CHECK(second.program_counts().loaded == 0);
    CHECK(second.program_counts().rejected == rejected);
    CHECK(second.program_counts().built == 1);
    CHECK(second.program_counts().stored == 1);
    // The rewritten entry serves the next context.
    ocl::Context third(*device, tmp.path());
    CHECK(run_affine(third, kSource, kOptions) == expected_affine(1.0f));
    CHECK(third.program_counts().loaded == 1);
}

TEST_CASE("opencl: the program cache misses for other options or another source", "[opencl][cache]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const ocl::DeviceInfo* const device = &test::first_opencl().context()->info();
    const TempDir tmp;
    {
        ocl::Context first(*device, tmp.path());
        run_affine(first, kSource, kOptions);
    }
    ocl::Context second(*device, tmp.path());
    CHECK(run_affine(second, kSource, "-cl-std=CL1.2 -DOFFSET=2.0f") == expected_affine(2.0f));
    CHECK(second.program_counts().loaded == 0);
    CHECK(second.program_counts().built == 1);
    const std::string other_source = kSource + "// another source, the same kernel\n";
    CHECK(run_affine(second, other_source, kOptions) == expected_affine(1.0f));
    CHECK(second.program_counts().loaded == 0);
    CHECK(second.program_counts().built == 2);
    CHECK(run_affine(second, kSource, kOptions) == expected_affine(1.0f));
    CHECK(second.program_counts().loaded == 1);
    CHECK(files_in(tmp.path()).size() == 3);
    // The key holds what makes a binary valid: the driver's version among them.
    const std::string key = second.program_key(kSource, kOptions);
    CHECK(key.find(device->driver) != std::string::npos);
    CHECK(key.find(device->name) != std::string::npos);
}

TEST_CASE("opencl: HEMIRAD_CACHE_DIR=off keeps no program on the disk", "[opencl][cache]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const ocl::DeviceInfo* const device = &test::first_opencl().context()->info();
    const TempDir tmp;
    ScopedEnv off("HEMIRAD_CACHE_DIR", "off");
    ScopedEnv xdg("XDG_CACHE_HOME", (tmp / "xdg").c_str());
    ScopedEnv home("HOME", (tmp / "home").c_str());
    ocl::Context context(*device);  // the directory from the environment
    CHECK(!context.program_cache().enabled());
    CHECK(run_affine(context, kSource, kOptions) == expected_affine(1.0f));
    CHECK(context.program_counts().built == 1);
    CHECK(context.program_counts().stored == 0);
    const auto written = files_in(tmp.path());
    CHECK(written.empty());
}
