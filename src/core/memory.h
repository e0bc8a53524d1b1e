// What memory a bake may use: the machine's (and its cgroup's) available memory, and byte
// counts read from and written for people.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace hemirad {

// The memory this process may still allocate: /proc/meminfo's MemAvailable, lowered to what a
// cgroup limit leaves (v2 memory.max − memory.current, or v1 limit − usage). nullopt where none
// of these can be read.
std::optional<double> available_memory();

// "1.2 GB", "340 MB", "12 KB", "512 bytes" (decimal units, three significant digits); infinity
// (a count that overflowed) says so.
std::string format_bytes(double bytes);

// "8G", "512M", "100k", "2.5GB", "1e9", "123456": bytes (K, M, G, T are powers of 1000; KiB,
// MiB, GiB, TiB of 1024). Throws std::invalid_argument for anything else, including a size
// that is not finite or not positive.
double parse_bytes(const std::string& text);

}  // namespace hemirad
