// Reading a file a user or a scene names, safely: only regular files are read. A FIFO, a device
// (/dev/zero, a terminal), a socket or a directory where a file belongs is refused by its type,
// and opening never blocks (a FIFO without a writer would hang open() and ignore SIGINT).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace hemirad {

class RegularFile {
public:
    // Opens `path` for reading. Throws InputError("<name>: <problem>"): "cannot open: No such file
    // or directory", "is a FIFO, not a regular file", "is a directory, not a regular file", …
    RegularFile(const std::filesystem::path& path, const std::string& name);
    ~RegularFile();
    RegularFile(const RegularFile&) = delete;
    RegularFile& operator=(const RegularFile&) = delete;

    std::uint64_t size() const { return size_; }  // bytes, when it was opened

    // Reads `count` bytes at `offset` into `out`; false when the file ends first or a read fails.
    bool read(std::uint64_t offset, std::size_t count, void* out) const;

    // Throws InputError("<name>: <problem>") for a failed or short read.
    void read_exactly(std::uint64_t offset, std::size_t count, void* out) const;

private:
    int fd_ = -1;
    std::uint64_t size_ = 0;
    std::string name_;
};

// Why `path` cannot be read as a regular file ("cannot open: No such file or directory", "is a
// FIFO, not a regular file"), or empty when it can. Opens nothing (stat only), so it never blocks.
std::string regular_file_problem(const std::filesystem::path& path);

// The whole of a regular file, at most `limit` bytes; throws InputError("<name>: <problem>") when
// it is not one, cannot be read, or is larger than `limit` ("… bytes, above the limit of …").
std::vector<unsigned char> read_regular_file(const std::filesystem::path& path, const std::string& name,
                                             std::uint64_t limit);

}  // namespace hemirad
