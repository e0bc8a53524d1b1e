// What the in-process bake benchmarks (bench_effects, bench_image) share: a temporary directory
// for their bakes and reading a bake's report back.
#pragma once

#include <fmt/core.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/error.h"

namespace hemirad::bench {

// A fresh directory under the system's temporary directory, removed with everything in it when
// this goes out of scope (on a throw too).
class TempDir {
public:
    explicit TempDir(const std::string& prefix) {
        const std::filesystem::path base = std::filesystem::temp_directory_path();
        for (int i = 0;; ++i) {
            const std::filesystem::path p = base / fmt::format("{}-{}-{}", prefix, static_cast<long>(getpid()), i);
            std::error_code ec;
            if (std::filesystem::create_directory(p, ec)) {
                path_ = p;
                return;
            }
            if (ec || i >= 1000)
                throw InternalError(fmt::format("{}: cannot create a temporary directory", base.string()));
        }
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    ~TempDir() {
        std::error_code ec;  // destructors never throw
        std::filesystem::remove_all(path_, ec);
    }
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
};

inline nlohmann::ordered_json read_report(const std::filesystem::path& file) {
    std::ifstream in(file);
    if (!in) throw InternalError(fmt::format("{}: the bake wrote no report", file.string()));
    return nlohmann::ordered_json::parse(in);
}

}  // namespace hemirad::bench
