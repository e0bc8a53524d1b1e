// Available memory from /proc and the cgroup files; byte counts in words.
#include "core/memory.h"

#include <sys/resource.h>

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace hemirad {
namespace {

// The first number in a file ("max" and unreadable files give nullopt).
std::optional<double> read_number(const std::string& file) {
    std::ifstream in(file);
    std::string word;
    if (!(in >> word) || word.empty() || !std::isdigit(static_cast<unsigned char>(word[0]))) return std::nullopt;
    try {
        return std::stod(word);
    } catch (const std::exception&) {
        return std::nullopt;
    }
}

// The value after `key` in a file of "key value" lines (/proc/meminfo in kB, memory.stat in bytes).
std::optional<double> field(const std::string& file, const std::string& key) {
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream fields(line);
        std::string name;
        double value = 0.0;
        if (fields >> name >> value && name == key) return value;
    }
    return std::nullopt;
}

std::optional<double> meminfo(const std::string& key) {
    const std::optional<double> kb = field("/proc/meminfo", key);
    return kb ? std::optional<double>(*kb * 1024.0) : std::nullopt;
}

// One cgroup's memory limit and what it holds that cannot be reclaimed (its usage less the
// inactive file cache, as container runtimes count it: the page cache of files a bake or a build
// read would otherwise look like memory in use).
struct CgroupMemory {
    std::optional<double> limit, used;
};

// The memory cgroups this process is in (v2, or v1's memory controller), itself and its ancestors
// up to the mount's root, which is also the container's own cgroup where /proc/self/cgroup names
// a path the mount does not show.
std::vector<CgroupMemory> cgroups() {
    std::vector<CgroupMemory> found;
    const auto add = [&](const std::string& dir, bool v2) {
        CgroupMemory c;
        const std::optional<double> limit = read_number(dir + (v2 ? "/memory.max" : "/memory.limit_in_bytes"));
        if (!limit || *limit > 1e18) return;  // "max", or v1's huge number for none
        c.limit = limit;
        const std::optional<double> usage = read_number(dir + (v2 ? "/memory.current" : "/memory.usage_in_bytes"));
        const std::optional<double> inactive = field(dir + "/memory.stat", v2 ? "inactive_file" : "total_inactive_file");
        if (usage) c.used = std::max(0.0, *usage - inactive.value_or(0.0));
        found.push_back(c);
    };
    std::ifstream in("/proc/self/cgroup");
    std::string line;
    while (std::getline(in, line)) {
        // "0::/path" (v2) or "N:controllers:/path" (v1, the one whose controllers include memory)
        const std::size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
        if (b == std::string::npos) continue;
        const std::string controllers = line.substr(a + 1, b - a - 1);
        std::string path = line.substr(b + 1);
        const bool v2 = controllers.empty();
        bool memory = v2;
        for (std::size_t k = 0; k <= controllers.size();) {
            const std::size_t comma = std::min(controllers.find(',', k), controllers.size());
            memory = memory || controllers.substr(k, comma - k) == "memory";
            k = comma + 1;
        }
        if (!memory) continue;
        const std::string root = v2 ? "/sys/fs/cgroup" : "/sys/fs/cgroup/memory";
        while (!path.empty() && path != "/") {
            add(root + path, v2);
            path = path.substr(0, path.rfind('/'));
        }
        add(root, v2);
    }
    return found;
}

}  // namespace

std::optional<double> machine_memory() {
    std::optional<double> total = meminfo("MemTotal:");
    for (const CgroupMemory& c : cgroups()) total = total ? std::min(*total, *c.limit) : *c.limit;
    return total;
}

std::optional<double> available_memory() {
    std::optional<double> available = meminfo("MemAvailable:");
    for (const CgroupMemory& c : cgroups()) {
        if (!c.used) continue;
        const double left = std::max(0.0, *c.limit - *c.used);
        available = available ? std::min(*available, left) : left;
    }
    return available;
}

double peak_memory() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return double(usage.ru_maxrss) * 1024.0;  // kilobytes on Linux
}

std::string format_bytes(double bytes) {
    if (!std::isfinite(bytes)) return "more bytes than can be counted";
    if (bytes < 1e3) return fmt::format("{:.0f} bytes", bytes);
    static const char* units[] = {"KB", "MB", "GB", "TB", "PB"};
    int u = 0;
    double v = bytes / 1e3;
    while (v >= 999.5 && u < 4) {  // beyond PB: 1.2e+03 PB
        v /= 1e3;
        ++u;
    }
    return fmt::format("{:.3g} {}", v, units[u]);
}

double parse_bytes(const std::string& text) {
    // A plain decimal number (digits, a point, an exponent: no sign, hex, nan or inf), then a unit.
    static const std::regex kSize(R"(((?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)([A-Za-z]*))");
    std::smatch match;
    if (!std::regex_match(text, match, kSize)) throw std::invalid_argument("expected a size such as 8G, 512M or 1e9 (bytes)");
    const double value = std::strtod(match[1].str().c_str(), nullptr);  // overflow gives inf, refused below
    std::string unit = match[2].str();
    for (char& c : unit) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    double scale = 0.0;
    if (unit.empty() || unit == "B") scale = 1.0;
    const char* prefixes = "KMGT";
    for (int i = 0; i < 4; ++i) {
        const std::string p(1, prefixes[i]);
        if (unit == p || unit == p + "B") scale = std::pow(1e3, i + 1);
        if (unit == p + "IB" || unit == p + "I") scale = std::pow(1024.0, i + 1);
    }
    if (scale == 0.0) throw std::invalid_argument("unknown unit '" + match[2].str() + "' (K, M, G, T or KiB, MiB, GiB, TiB)");
    const double bytes = value * scale;
    if (!std::isfinite(bytes)) throw std::invalid_argument("the size must be finite");
    if (!(bytes >= 1e6)) throw std::invalid_argument("the size must be at least 1M (1 MB): no bake fits in less");
    return bytes;
}

}  // namespace hemirad
