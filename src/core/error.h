// Error types: the one catch point in cli/ maps each to an exit code and one clear line.
#pragma once

#include <stdexcept>
#include <string>

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

}  // namespace hemirad
