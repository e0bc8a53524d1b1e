// The on-disk program binary cache (see program_cache.h).
#include "cl/program_cache.h"

#include <fcntl.h>
#include <fmt/core.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string_view>
#include <system_error>

#include "core/regular_file.h"

namespace hemirad::ocl {
namespace fs = std::filesystem;
namespace {

// An entry: magic (its last byte the format version), then key size, binary size and a checksum of
// key and binary (u64 each, host order: the key names the host's device), then key and binary.
constexpr char kMagic[8] = {'H', 'R', 'C', 'L', 'B', 'I', 'N', static_cast<char>('0' + kProgramCacheFormat)};
constexpr std::size_t kHeaderSize = sizeof kMagic + 3 * sizeof(std::uint64_t);

std::uint64_t checksum(const std::string& key, const unsigned char* binary, std::size_t size) {
    return fnv1a64(binary, size, fnv1a64(key.data(), key.size()));
}

bool write_all(int fd, const void* data, std::size_t size) {
    const auto* bytes = static_cast<const char*>(data);
    while (size > 0) {
        const ssize_t n = ::write(fd, bytes, size);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        bytes += n;
        size -= static_cast<std::size_t>(n);
    }
    return true;
}

}  // namespace

std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t h) {
    const auto* bytes = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) h = (h ^ bytes[i]) * 0x100000001b3ull;
    return h;
}

std::optional<fs::path> program_cache_directory(const std::string& device_type) {
    const auto set = [](const char* name) -> const char* {
        const char* value = std::getenv(name);
        return value && *value ? value : nullptr;
    };
    if (const char* dir = set("HEMIRAD_CACHE_DIR")) {
        if (std::string_view(dir) == "off") return std::nullopt;
        return fs::path(dir);
    }
    if (device_type == "cpu") return std::nullopt;
    // The XDG base directory spec ignores a relative XDG_CACHE_HOME.
    if (const char* xdg = set("XDG_CACHE_HOME"); xdg && fs::path(xdg).is_absolute()) return fs::path(xdg) / "hemirad";
    if (const char* home = set("HOME")) return fs::path(home) / ".cache" / "hemirad";
    return std::nullopt;
}

fs::path ProgramCache::entry_path(const std::string& key) const {
    if (!dir_) return {};
    return *dir_ / fmt::format("{:016x}.clbin", fnv1a64(key.data(), key.size()));
}

std::optional<std::vector<unsigned char>> ProgramCache::load(const std::string& key) const {
    if (!dir_) return std::nullopt;
    try {
        // RegularFile: a FIFO or directory left where an entry belongs is refused, never waited on.
        const RegularFile in(entry_path(key), "program cache entry");
        char magic[sizeof kMagic];
        std::uint64_t sizes[3];  // key, binary, checksum
        if (in.size() < kHeaderSize || !in.read(0, sizeof magic, magic) ||
            std::memcmp(magic, kMagic, sizeof kMagic) != 0 || !in.read(sizeof magic, sizeof sizes, sizes))
            return std::nullopt;
        // Compared with the file's size before anything is allocated, so a damaged size cannot ask
        // for terabytes; an entry cut short or grown is refused here too.
        if (sizes[0] != key.size() || sizes[1] > in.size() || in.size() - kHeaderSize != sizes[0] + sizes[1])
            return std::nullopt;
        std::string stored(key.size(), '\0');
        std::vector<unsigned char> binary(static_cast<std::size_t>(sizes[1]));
        if (!in.read(kHeaderSize, stored.size(), stored.data()) || stored != key ||
            !in.read(kHeaderSize + key.size(), binary.size(), binary.data()) ||
            checksum(key, binary.data(), binary.size()) != sizes[2])
            return std::nullopt;
        return binary;
    } catch (const std::exception&) {
        return std::nullopt;  // no entry, or one that cannot be opened: a miss
    }
}

bool ProgramCache::store(const std::string& key, const std::vector<unsigned char>& binary) const {
    if (!dir_ || binary.empty()) return false;
    std::error_code ec;
    fs::create_directories(*dir_, ec);
    if (ec) return false;
    const fs::path file = entry_path(key);
    // A unique temporary name in the same directory (so the rename stays on one file system), that
    // bakes storing the same entry at once do not share.
    std::string temp = file.string() + ".tmp-XXXXXX";
    const int fd = ::mkstemp(temp.data());
    if (fd < 0) return false;
    const std::uint64_t sizes[3] = {key.size(), binary.size(), checksum(key, binary.data(), binary.size())};
    bool ok = write_all(fd, kMagic, sizeof kMagic) && write_all(fd, sizes, sizeof sizes) &&
              write_all(fd, key.data(), key.size()) && write_all(fd, binary.data(), binary.size());
    ok = ::close(fd) == 0 && ok;
    // Not flushed to the disk: after a power cut a lost or zeroed entry fails its checksum and is
    // rebuilt, which is all a cache owes.
    if (ok) fs::rename(temp, file, ec);
    if (!ok || ec) {
        fs::remove(temp, ec);
        return false;
    }
    return true;
}

}  // namespace hemirad::ocl
