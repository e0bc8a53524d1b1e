// Wall-clock timing for the bake's report and the benchmarks.
#pragma once

#include <chrono>

namespace hemirad {

using Clock = std::chrono::steady_clock;

// Seconds from `start` to now.
inline double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace hemirad
