// Counts in messages: "1,937 zero-area triangles", digits grouped by threes whatever the locale.
#pragma once

#include <cstdint>
#include <string>

namespace hemirad {

// 1937 -> "1,937".
inline std::string grouped(std::uint64_t n) {
    std::string digits = std::to_string(n), out;
    for (std::size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
        out += digits[i];
    }
    return out;
}

// (1937, "triangle") -> "1,937 triangles"; (1, "triangle") -> "1 triangle". `plural` where
// adding an s is wrong ("meshes").
inline std::string counted(std::uint64_t n, const std::string& singular, const std::string& plural = "") {
    return grouped(n) + " " + (n == 1 ? singular : plural.empty() ? singular + "s" : plural);
}

}  // namespace hemirad
