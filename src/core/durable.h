// Making a written file survive a crash of the machine, not only of the process: its bytes are
// flushed to the disk before it is renamed into place, and the rename itself after.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <filesystem>

namespace hemirad {

// Flushes `path` (a file or a directory) to the disk. False when it cannot be opened or synced;
// callers treat that as a write that failed.
inline bool sync_to_disk(const std::filesystem::path& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
    const bool ok = ::fsync(fd) == 0;
    return ::close(fd) == 0 && ok;
}

}  // namespace hemirad
