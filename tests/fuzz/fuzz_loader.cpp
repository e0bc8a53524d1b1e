// libFuzzer target for the scene loader: any bytes, as a .gltf or (with the binary magic) a .glb,
// must either load or be refused with an InputError; anything else (a crash, a sanitizer report,
// another exception) is a finding. Built and run by run_fuzz.sh.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "scene/scene.h"

namespace {

// One scratch file per process, named for its kind: the loader picks the parser by extension.
std::filesystem::path scratch(bool binary) {
    static const std::string stem =
        (std::filesystem::temp_directory_path() / ("hemirad-fuzz-" + std::to_string(getpid()))).string();
    return stem + (binary ? ".glb" : ".gltf");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
    const std::filesystem::path file = scratch(binary);
    {
        std::ofstream out(file, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    }
    try {
        const hemirad::scene::Scene scene = hemirad::scene::load(file);
        (void)scene;
    } catch (const hemirad::InputError&) {
        // Refused with a message: what bad input should get.
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_loader: not an InputError: %s\n", e.what());
        std::abort();
    }
    return 0;
}
