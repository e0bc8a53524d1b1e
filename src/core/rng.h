// Seeded, stateless randomness: every random choice is a pure function of (seed, counter),
// so a bake is reproducible and any engine can recompute the same numbers.
#pragma once

#include <cstdint>

namespace hemirad {

// SplitMix64 finaliser (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
constexpr std::uint64_t mix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

// Uniform double in [0, 1) from (seed, stream, counter).
constexpr double uniform01(std::uint64_t seed, std::uint64_t stream, std::uint64_t counter) {
    const std::uint64_t h = mix64(mix64(seed ^ mix64(stream)) ^ counter);
    return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);  // 53 bits
}

}  // namespace hemirad
