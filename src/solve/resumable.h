// A solver whose whole state can be written to a checkpoint and read back (`hemirad bake
// --checkpoint` / `--resume`), and the raw reads and writes both solvers' states are made of.
#pragma once

#include <cstdint>
#include <istream>
#include <ostream>
#include <stdexcept>
#include <vector>

namespace hemirad::solve {

class Resumable {
public:
    virtual ~Resumable() = default;
    // The state, raw (doubles bit for bit), so that a solver of the same mesh, engine and
    // settings that load()s it goes on exactly as this one would have.
    virtual void save(std::ostream& out) const = 0;
    // Restores what save() wrote for this mesh; throws std::runtime_error when the stream ends
    // early or does not fit this mesh.
    virtual void load(std::istream& in) = 0;
};

namespace state_io {

template <class T>
void put(std::ostream& out, const T& value) {
    out.write(reinterpret_cast<const char*>(&value), sizeof value);
}

template <class T>
void get(std::istream& in, T& value) {
    if (!in.read(reinterpret_cast<char*>(&value), sizeof value)) throw std::runtime_error("the checkpoint ends early");
}

// A vector as its length, then its items.
template <class T>
void put_vector(std::ostream& out, const std::vector<T>& v) {
    put(out, static_cast<std::uint64_t>(v.size()));
    out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(T)));
}

// Reads put_vector's bytes into `v`: exactly `expected` items, or at most `most` when `expected`
// is kAny (a length beyond either means a checkpoint of another mesh, or damaged).
constexpr std::uint64_t kAny = ~std::uint64_t{0};
template <class T>
void get_vector(std::istream& in, std::vector<T>& v, std::uint64_t expected, std::uint64_t most = kAny) {
    std::uint64_t n = 0;
    get(in, n);
    if ((expected != kAny && n != expected) || (expected == kAny && n > most))
        throw std::runtime_error("the checkpoint is for another mesh");
    v.resize(static_cast<std::size_t>(n));
    if (!in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T))))
        throw std::runtime_error("the checkpoint ends early");
}

}  // namespace state_io
}  // namespace hemirad::solve
