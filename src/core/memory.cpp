// Available memory from /proc and the cgroup files; byte counts in words.
#include "core/memory.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace hemirad {
namespace {

// The first number in a file ("max" and unreadable files give nullopt).
std::optional<double> read_number(const char* file) {
    std::ifstream in(file);
    std::string word;
    if (!(in >> word) || word.empty() || !std::isdigit(static_cast<unsigned char>(word[0]))) return std::nullopt;
    try {
        return std::stod(word);
    } catch (const std::exception&) {
        return std::nullopt;
    }
}

std::optional<double> meminfo_available() {
    std::ifstream in("/proc/meminfo");
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream fields(line);
        std::string key;
        double kb = 0.0;
        if (fields >> key >> kb && key == "MemAvailable:") return kb * 1024.0;
    }
    return std::nullopt;
}

}  // namespace

std::optional<double> available_memory() {
    std::optional<double> available = meminfo_available();
    const auto lower = [&](std::optional<double> limit, std::optional<double> used) {
        if (!limit || !used || *limit > 1e18) return;  // no limit (v1 writes a huge number)
        const double left = std::max(0.0, *limit - *used);
        available = available ? std::min(*available, left) : left;
    };
    lower(read_number("/sys/fs/cgroup/memory.max"), read_number("/sys/fs/cgroup/memory.current"));
    lower(read_number("/sys/fs/cgroup/memory/memory.limit_in_bytes"),
          read_number("/sys/fs/cgroup/memory/memory.usage_in_bytes"));
    return available;
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
    if (!std::isfinite(bytes) || !(bytes > 0.0)) throw std::invalid_argument("the size must be positive and finite");
    return bytes;
}

}  // namespace hemirad
