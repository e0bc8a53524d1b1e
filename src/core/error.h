// Error types: the one catch point in cli/ maps each to an exit code and one clear line.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

namespace hemirad {

// Bad input or usage: a malformed scene, an invalid option. Exit code 2.
// The message already names the file and the problem ("scene.gltf: accessor 3 out of range").
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// Internal or device failure. Exit code 1.
class InternalError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// A file that could not be written (a full disk, no permission): exit code 1, the message as
// it is ("render.png: written incompletely ..."), not labelled an internal error.
class OutputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// `text` as one printable line: control characters (a newline, or a terminal escape, that the
// names in a file or on the command line may hold) become \xNN, so that a message the CLI prints
// stays one line and cannot rewrite the terminal. Other bytes, UTF-8 included, are kept.
inline std::string printable(std::string_view text) {
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out;
    out.reserve(text.size());
    for (const char c : text) {
        const auto byte = static_cast<unsigned char>(c);
        if (byte < 0x20 || byte == 0x7f) {
            out += "\\x";
            out += kHex[byte >> 4];
            out += kHex[byte & 0xf];
        } else {
            out += c;
        }
    }
    return out;
}

}  // namespace hemirad
