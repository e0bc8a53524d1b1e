// Regular files only, opened without blocking (see regular_file.h).
#include "core/regular_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <limits>

#include <fmt/core.h>

#include "core/error.h"

namespace hemirad {
namespace {

// What a file that is not a regular one is, for "<name> is a FIFO, not a regular file".
std::string type_problem(mode_t mode) {
    const char* what = S_ISDIR(mode)    ? "a directory"
                       : S_ISFIFO(mode) ? "a FIFO"
                       : S_ISCHR(mode)  ? "a character device"
                       : S_ISBLK(mode)  ? "a block device"
                       : S_ISSOCK(mode) ? "a socket"
                                        : "not a file";
    return fmt::format("is {}, not a regular file", what);
}

}  // namespace

RegularFile::RegularFile(const std::filesystem::path& path, const std::string& name) : name_(name) {
    // O_NONBLOCK: open() of a FIFO without a writer returns at once instead of waiting (in a
    // wait SIGINT does not end); the type is then checked on what was opened, not on the name,
    // so a file swapped in between cannot slip through. Reads of a regular file ignore it.
    fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd_ < 0) throw InputError(fmt::format("{}: cannot open: {}", name_, std::strerror(errno)));
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
        const int error = errno;
        ::close(fd_);
        throw InputError(fmt::format("{}: cannot open: {}", name_, std::strerror(error)));
    }
    if (!S_ISREG(st.st_mode)) {
        ::close(fd_);
        throw InputError(fmt::format("{}: {}", name_, type_problem(st.st_mode)));
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
}

RegularFile::~RegularFile() {
    if (fd_ >= 0) ::close(fd_);
}

bool RegularFile::read(std::uint64_t offset, std::size_t count, void* out) const {
    auto* bytes = static_cast<unsigned char*>(out);
    while (count > 0) {
        if (offset > static_cast<std::uint64_t>(std::numeric_limits<off_t>::max())) return false;
        const ssize_t got = ::pread(fd_, bytes, count, static_cast<off_t>(offset));
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return false;
        bytes += got;
        count -= static_cast<std::size_t>(got);
        offset += static_cast<std::uint64_t>(got);
    }
    return true;
}

void RegularFile::read_exactly(std::uint64_t offset, std::size_t count, void* out) const {
    errno = 0;
    if (!read(offset, count, out))
        throw InputError(fmt::format("{}: cannot read: {}", name_,
                                     errno != 0 ? std::strerror(errno) : "the file ended early (was it changed?)"));
}

std::string regular_file_problem(const std::filesystem::path& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return std::string("cannot open: ") + std::strerror(errno);
    if (!S_ISREG(st.st_mode)) return type_problem(st.st_mode);
    return {};
}

std::vector<unsigned char> read_regular_file(const std::filesystem::path& path, const std::string& name,
                                             std::uint64_t limit) {
    const RegularFile file(path, name);
    if (file.size() > limit)
        throw InputError(fmt::format("{}: {} bytes, above the limit of {} bytes", name, file.size(), limit));
    std::vector<unsigned char> bytes(static_cast<std::size_t>(file.size()));
    file.read_exactly(0, bytes.size(), bytes.data());
    return bytes;
}

}  // namespace hemirad
