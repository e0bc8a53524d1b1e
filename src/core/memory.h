// What memory a bake may use: the machine's (and its cgroup's) total and available memory, and byte
// counts read from and written for people.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace hemirad {

// The memory this machine gives a process: /proc/meminfo's MemTotal, lowered to the smallest
// limit of the process's memory cgroup and its ancestors (v2 memory.max or v1
// memory.limit_in_bytes). It does not change from run to run, so what a bake plans by it does not
// either. nullopt where none of these can be read.
std::optional<double> machine_memory();

// The memory this process may still allocate now: /proc/meminfo's MemAvailable, lowered to what
// each of those cgroups' limits leaves beside its usage less its inactive file cache (which the
// kernel reclaims before it fails an allocation). nullopt where none of these can be read.
std::optional<double> available_memory();

// The most resident memory this process has held so far (getrusage's ru_maxrss), in bytes.
double peak_memory();

// "1.2 GB", "340 MB", "12 KB", "512 bytes" (decimal units, three significant digits); infinity
// (a count that overflowed) says so.
std::string format_bytes(double bytes);

// "8G", "512M", "100000k", "2.5GB", "1e9", "1234567": bytes (K, M, G, T are powers of 1000; KiB,
// MiB, GiB, TiB of 1024). Throws std::invalid_argument for anything else, including a size
// that is not finite or below 1 MB.
double parse_bytes(const std::string& text);

}  // namespace hemirad
