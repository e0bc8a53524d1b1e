// Checkpoints of a bake (see checkpoint.h). Layout: a magic line, the format version, the
// fingerprint (hash and settings), then the state (its stage's byte, then the solver's save()
// bytes or the stage's light, stage_checkpoint.h), its FNV-1a hash and an end marker.
#include "bake/checkpoint.h"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <optional>
#include <regex>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

#include "cl/program_cache.h"

#include "core/durable.h"
#include "core/error.h"
#include "core/regular_file.h"

namespace hemirad::bake {
namespace fs = std::filesystem;

namespace {

constexpr char kMagic[] = "hemirad checkpoint\n";
// Format versions: 2: the state's hash before the end marker; 3: progressive hit shares, round
// coverage; 4: running sums; 5: progressive shot counters per patch; 6: the stage's byte first;
// 7: no twin flags in the welded mesh; 8: a sparse gather's counts; 9: its coverage points.
constexpr std::uint32_t kFormat = 9;
constexpr std::uint64_t kEndMarker = 0x444e452d4b504b43ull;  // "CKPK-END"

// FNV-1a, 64 bits, over raw bytes.
class Hash {
public:
    template <class T>
    void add(const T& value) {
        add_bytes(&value, sizeof value);
    }
    void add_bytes(const void* data, std::size_t size) {
        const auto* bytes = static_cast<const unsigned char*>(data);
        for (std::size_t i = 0; i < size; ++i) h_ = (h_ ^ bytes[i]) * 0x100000001b3ull;
    }
    std::uint64_t value() const { return h_; }

private:
    std::uint64_t h_ = 0xcbf29ce484222325ull;
};

void add_polygon(Hash& h, const mesh::Polygon& p) {
    h.add(p.n);
    for (int i = 0; i < p.n; ++i) h.add(p.v[std::size_t(i)]);
}

void write_string(std::ostream& out, const std::string& s) {
    const auto n = static_cast<std::uint32_t>(s.size());
    out.write(reinterpret_cast<const char*>(&n), sizeof n);
    out.write(s.data(), static_cast<std::streamsize>(s.size()));
}

// Reads a file's bytes from `at` on, as written by the functions above: false where they end.
// The longest fingerprint (settings and mesh hash) a checkpoint may hold.
constexpr std::uint32_t kMaxFingerprint = 1u << 20;

class Cursor {
public:
    Cursor(const std::string& bytes, std::size_t at) : bytes_(bytes), at_(std::min(at, bytes.size())) {}
    template <class T>
    bool read(T& value) {
        if (bytes_.size() - at_ < sizeof value) return false;
        std::memcpy(&value, bytes_.data() + at_, sizeof value);
        at_ += sizeof value;
        return true;
    }
    bool read_string(std::string& s) {
        std::uint32_t n = 0;
        if (!read(n) || n > kMaxFingerprint || bytes_.size() - at_ < n) return false;
        s.assign(bytes_, at_, n);
        at_ += n;
        return true;
    }
    std::size_t at() const { return at_; }

private:
    const std::string& bytes_;
    std::size_t at_;
};

// A checkpoint's first bytes: enough for its magic, format and fingerprint (at most 1 MiB).
std::string read_head(const RegularFile& in) {
    std::string bytes(static_cast<std::size_t>(std::min<std::uint64_t>(in.size(), sizeof kMagic + 8 + kMaxFingerprint)), '\0');
    in.read_exactly(0, bytes.size(), bytes.data());
    return bytes;
}

// Whether an open file starts with the checkpoint magic.
bool starts_with_magic(const RegularFile& file) {
    char head[sizeof kMagic - 1];
    return file.size() >= sizeof head && file.read(0, sizeof head, head) &&
           std::memcmp(head, kMagic, sizeof head) == 0;
}

}  // namespace

void check_checkpoint_target(const fs::path& file) {
    const std::string name = file.string();
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(file, ec))) {
        // A new file: its directory must exist and take it, or the bake would fail at its first checkpoint.
        const fs::path dir = file.has_parent_path() ? file.parent_path() : fs::path(".");
        if (!fs::is_directory(dir, ec))
            throw InputError(fmt::format("{}: cannot write the checkpoint: its directory {} does not exist", name,
                                         dir.string()));
        if (::access(dir.c_str(), W_OK) != 0)
            throw InputError(fmt::format("{}: cannot write the checkpoint: {}", name, std::strerror(errno)));
        return;
    }
    // Only a checkpoint is replaced: a --checkpoint naming the scene or any other file must not destroy it.
    const RegularFile existing(file, name);
    if (!starts_with_magic(existing))
        throw InputError(fmt::format("{}: exists and is not a hemirad checkpoint; refusing to replace it (remove it "
                                     "or name another --checkpoint file)",
                                     name));
}

void check_resume_source(const fs::path& file) {
    if (!starts_with_magic(RegularFile(file, file.string())))
        throw InputError(fmt::format("{}: not a hemirad checkpoint", file.string()));
}

std::string bake_fingerprint(const mesh::Mesh& mesh, const std::string& settings) {
    Hash h;
    h.add(static_cast<std::uint64_t>(mesh.patches.size()));
    h.add(static_cast<std::uint64_t>(mesh.elements.size()));
    for (const mesh::Patch& p : mesh.patches) {
        add_polygon(h, p.poly);
        h.add(p.emission);
        h.add(p.first_element);
        h.add(p.element_count);
    }
    for (const mesh::Element& e : mesh.elements) {
        add_polygon(h, e.poly);
        h.add(e.rho);
        h.add(e.emission);
        h.add(e.patch);
        h.add(static_cast<std::uint8_t>(e.has_twin));
    }
    return fmt::format("mesh {:016x}, {}", h.value(), settings);
}

namespace {

// The checkpoint's bytes around `state`, to `file` through a temporary file and a rename.
void write_state(const fs::path& file, const std::string& fingerprint, const std::string& bytes) {
    check_checkpoint_target(file);  // again: the file may have changed since the bake began
    fs::path temp = file;
    temp += fmt::format(".tmp-{}", static_cast<long>(getpid()));
    {
        std::error_code ignored;
        fs::remove(temp, ignored);  // a leftover (even a FIFO, which opening would wait on) is this process's
        std::ofstream out(temp, std::ios::binary | std::ios::trunc);
        if (!out)
            throw InputError(fmt::format("{}: cannot write the checkpoint (does its directory exist?)", file.string()));
        out.write(kMagic, sizeof kMagic - 1);
        out.write(reinterpret_cast<const char*>(&kFormat), sizeof kFormat);
        write_string(out, fingerprint);
        Hash hash;
        hash.add_bytes(bytes.data(), bytes.size());
        const std::uint64_t sum = hash.value();
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
        out.write(reinterpret_cast<const char*>(&kEndMarker), sizeof kEndMarker);
        out.close();
        if (!out || !sync_to_disk(temp)) {
            std::error_code ec;
            fs::remove(temp, ec);
            throw InputError(fmt::format("{}: cannot write the checkpoint (disk full?)", file.string()));
        }
    }
    std::error_code ec;
    fs::rename(temp, file, ec);
    if (ec) {
        fs::remove(temp, ec);
        throw InputError(fmt::format("{}: cannot write the checkpoint: {}", file.string(), ec.message()));
    }
    // The rename too, so that after a power cut the file is this checkpoint or the one before.
    sync_to_disk(fs::absolute(file, ec).parent_path());
}

}  // namespace

const char* stage_name(Stage stage) {
    switch (stage) {
        case Stage::solving: return "solving";
        case Stage::solved: return "solved";
        case Stage::refined: return "refined";
        case Stage::gathered: return "gathered";
    }
    return "unknown";
}

void write_checkpoint(const fs::path& file, const std::string& fingerprint, const solve::Resumable& solver) {
    std::ostringstream state;
    state.put(static_cast<char>(Stage::solving));
    solver.save(state);
    write_state(file, fingerprint, state.str());
}

void write_stage_checkpoint(const fs::path& file, const std::string& fingerprint, Stage stage,
                            const std::string& state) {
    std::string bytes(1, static_cast<char>(stage));
    bytes += state;
    write_state(file, fingerprint, bytes);
}

Stage checkpoint_stage(const std::string& state) {
    return state.empty() ? Stage::solving : static_cast<Stage>(static_cast<std::uint8_t>(state[0]));
}

std::string stage_state(const std::string& state) { return state.empty() ? state : state.substr(1); }

std::optional<CheckpointBatch> checkpoint_batch(const fs::path& file) {
    try {
        const std::string bytes = read_head(RegularFile(file, file.string()));
        if (bytes.compare(0, sizeof kMagic - 1, kMagic) != 0) return std::nullopt;
        Cursor s(bytes, sizeof kMagic - 1);
        std::uint32_t format = 0;
        std::string saved;
        if (!s.read(format) || format != kFormat || !s.read_string(saved)) return std::nullopt;
        static const std::regex kBatch(R"(, batch (\d{1,3})(?: within ([0-9.eE+-]{1,32}) of the largest)?, )");
        std::smatch m;
        if (!std::regex_search(saved, m, kBatch)) return std::nullopt;
        CheckpointBatch b;
        b.batch = std::stoi(m[1]);
        if (m[2].matched) b.share = std::stod(m[2]);
        return b;
    } catch (const std::exception&) {
        return std::nullopt;  // read_checkpoint says what is wrong with it
    }
}

// The head of a checkpoint (`bytes`, its first bytes at least): the magic, the format, and the
// fingerprint of the bake it was made for, which must be `fingerprint`. Returns where the state
// begins.
std::size_t check_head(const std::string& bytes, const fs::path& file, const std::string& fingerprint) {
    if (bytes.compare(0, sizeof kMagic - 1, kMagic) != 0)
        throw InputError(fmt::format("{}: not a hemirad checkpoint", file.string()));
    Cursor s(bytes, sizeof kMagic - 1);
    std::uint32_t format = 0;
    if (!s.read(format) || format != kFormat)
        throw InputError(
            fmt::format("{}: checkpoint format {} (this hemirad reads format {})", file.string(), format, kFormat));
    std::string saved;
    if (!s.read_string(saved))
        throw InputError(fmt::format("{}: the checkpoint is damaged (it ends early)", file.string()));
    if (saved != fingerprint)
        throw InputError(fmt::format("{}: the checkpoint is of another bake: it was made for [{}], this bake is [{}]",
                                     file.string(), saved, fingerprint));
    return s.at();
}

std::string read_checkpoint(const fs::path& file, const std::string& fingerprint) {
    // A regular file only (a directory or FIFO is refused, never waited on), read once into the
    // string that is returned: a matrix bake's checkpoint can be large.
    const RegularFile in(file, file.string());
    // Its head first: a file of another bake, or of anything else, is refused without reading it
    // whole (a 3 GiB one was).
    std::string bytes = read_head(in);
    const std::size_t begin = check_head(bytes, file, fingerprint);
    bytes.resize(static_cast<std::size_t>(in.size()));
    in.read_exactly(0, bytes.size(), bytes.data());
    std::uint64_t end = 0, sum = 0;
    if (bytes.size() >= begin + sizeof sum + sizeof end) {
        std::memcpy(&end, bytes.data() + bytes.size() - sizeof end, sizeof end);
        std::memcpy(&sum, bytes.data() + bytes.size() - sizeof end - sizeof sum, sizeof sum);
    }
    if (end != kEndMarker) throw InputError(fmt::format("{}: the checkpoint is damaged (no end marker)", file.string()));
    const std::size_t length = bytes.size() - sizeof end - sizeof sum - begin;
    Hash hash;
    hash.add_bytes(bytes.data() + begin, length);
    if (hash.value() != sum)
        throw InputError(fmt::format("{}: the checkpoint is damaged (its checksum does not match)", file.string()));
    if (length < 1 || static_cast<std::uint8_t>(bytes[begin]) > static_cast<std::uint8_t>(Stage::gathered))
        throw InputError(fmt::format("{}: the checkpoint is damaged (no stage)", file.string()));
    bytes.resize(begin + length);  // in place: the state alone
    bytes.erase(0, begin);
    return bytes;
}

void restore(solve::Resumable& solver, const std::string& state, const fs::path& file) {
    if (checkpoint_stage(state) != Stage::solving)
        throw InputError(fmt::format("{}: the checkpoint holds the {} stage, not the solver's", file.string(),
                                     stage_name(checkpoint_stage(state))));
    std::istringstream in(state);
    in.get();  // the stage
    try {
        solver.load(in);
    } catch (const std::runtime_error& e) {
        throw InputError(fmt::format("{}: the checkpoint is damaged ({})", file.string(), e.what()));
    }
    if (in.peek() != std::char_traits<char>::eof())
        throw InputError(fmt::format("{}: the checkpoint is damaged (bytes left over)", file.string()));
}

std::optional<fs::path> checkpoint_directory() {
    const std::optional<fs::path> cache = ocl::program_cache_directory();
    if (!cache) return std::nullopt;
    return *cache / "checkpoints";
}

fs::path automatic_checkpoint_file(const fs::path& dir, const std::string& fingerprint) {
    return dir / fmt::format("{:016x}.ckpt", ocl::fnv1a64(fingerprint.data(), fingerprint.size()));
}

int prune_checkpoints(const fs::path& dir, const fs::path& keep, double max_age_days, std::uintmax_t max_bytes) {
    struct Entry {
        fs::path path;
        fs::file_time_type written;
        std::uintmax_t bytes;
    };
    std::vector<Entry> entries;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const fs::path& path = it->path();
        const std::string name = path.filename().string();
        // Ours only: NAME.ckpt, and NAME.ckpt.tmp-PID left by a write that was killed.
        if (name.size() < 21 || name.compare(16, 5, ".ckpt") != 0 || path == keep) continue;
        std::error_code e;
        if (!it->is_regular_file(e)) continue;
        const auto written = it->last_write_time(e);
        const auto bytes = it->file_size(e);
        if (!e) entries.push_back({path, written, bytes});
    }
    const auto now = fs::file_time_type::clock::now();
    const auto max_age = std::chrono::duration_cast<fs::file_time_type::duration>(
        std::chrono::duration<double>(max_age_days * 86400.0));
    std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.written > b.written; });
    int removed = 0;
    std::uintmax_t total = 0;
    for (const Entry& e : entries) {
        // A temporary file may be another bake's, being written: only age removes it.
        const bool temporary = e.path.extension() != ".ckpt";
        const bool stale = now - e.written > max_age, over = !temporary && total + e.bytes > max_bytes;
        std::error_code ignored;
        if ((stale || over) && fs::remove(e.path, ignored)) {
            ++removed;
            continue;
        }
        if (!temporary) total += e.bytes;
    }
    return removed;
}

}  // namespace hemirad::bake
