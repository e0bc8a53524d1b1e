// A directory of built OpenCL program binaries kept across runs, so a second bake loads its
// kernels instead of compiling them. Entries are keyed by everything that makes a binary valid.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace hemirad::ocl {

// The entry file format's version; part of every key, so a new format never reads an old entry.
inline constexpr int kProgramCacheFormat = 1;

// The cache directory: $HEMIRAD_CACHE_DIR (`off` turns the cache off), else none for a device of
// type "cpu", else $XDG_CACHE_HOME/hemirad, else $HOME/.cache/hemirad; nullopt when off or none
// is known. CPUs are left out by default because PoCL keeps its own binaries (~/.cache/pocl):
// ours saved 0.15 s of a warm start, while asking PoCL for a binary to store made it compile
// every kernel for every work-group size, 7 s more on a cold one (2 EPYC cores).
std::optional<std::filesystem::path> program_cache_directory(const std::string& device_type = "");

// One file per key under `dir`, created on the first store. Every failure to read or write is a
// miss, never an error: a cache that cannot be used only costs a build. A Context owns one.
class ProgramCache {
public:
    explicit ProgramCache(std::optional<std::filesystem::path> dir) : dir_(std::move(dir)) {}

    bool enabled() const { return dir_.has_value(); }

    // The file that holds `key`'s entry (not necessarily existing); empty when disabled.
    std::filesystem::path entry_path(const std::string& key) const;

    // The binary stored under `key`, or nullopt: no entry, or one that is truncated, damaged
    // (checksum) or written for another key (file names are a hash; the entry holds the key).
    std::optional<std::vector<unsigned char>> load(const std::string& key) const;

    // Stores `binary` under `key`, replacing any entry, through a temporary file renamed into
    // place so that a concurrent load sees the old entry or the new one, never a part. False when
    // it could not (no directory, read-only, disk full).
    bool store(const std::string& key, const std::vector<unsigned char>& binary) const;

private:
    std::optional<std::filesystem::path> dir_;
};

// FNV-1a, 64 bits: entry file names and checksums. Not collision-proof, which is why an entry
// holds its whole key and a load compares it.
std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t h = 0xcbf29ce484222325ull);

}  // namespace hemirad::ocl
