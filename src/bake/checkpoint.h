// `hemirad bake --checkpoint FILE` / `--resume FILE`: the solver's state on disk (the
// progressive solver's, or the matrix solver's rows), so that a bake killed at any moment goes on
// from its last checkpoint and ends with exactly the numbers of an uninterrupted bake.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "mesh/mesh.h"
#include "solve/resumable.h"

namespace hemirad::bake {

// What decides a bake's numbers: the mesh (every patch's and element's geometry,
// reflectance and emission, so the scene file, its buffers and the effects applied to it) and
// `settings`, the solver and engine settings as text. A checkpoint resumes only the same bake.
std::string bake_fingerprint(const mesh::Mesh& mesh, const std::string& settings);

// Before a bake does any work: that --checkpoint FILE can be written, and is either new or a
// hemirad checkpoint (recognised by its magic) — never the scene or any other file, which writing
// would destroy. Throws InputError (exit 2) naming the file otherwise.
void check_checkpoint_target(const std::filesystem::path& file);

// Before a bake does any work: that --resume FILE is a readable hemirad checkpoint (a regular
// file with the magic; a directory or FIFO is refused, not waited on). Throws InputError.
void check_resume_source(const std::filesystem::path& file);

// Writes the solver's state to `file` atomically (a temporary file beside it, then a rename), so
// a bake killed while writing leaves the previous checkpoint whole. Throws InputError when the
// file cannot be written, or has become something other than a checkpoint since the bake began.
void write_checkpoint(const std::filesystem::path& file, const std::string& fingerprint,
                      const solve::Resumable& solver);

// Reads `file` and returns the solver state it holds, before the bake writes anything. Throws
// InputError (exit 2, naming the file) when it cannot be read, is not a hemirad checkpoint, is
// cut short, or belongs to another scene or settings.
std::string read_checkpoint(const std::filesystem::path& file, const std::string& fingerprint);

// The batch a progressive bake's checkpoint was made with (its fingerprint says), or nullopt for
// a matrix bake's or a file that is no readable checkpoint: a resumed bake that is not given
// --batch takes it, so that it may resume with another number of devices or ranks.
std::optional<int> checkpoint_batch(const std::filesystem::path& file);

// Loads a state from read_checkpoint into the solver; InputError naming `file` if it is damaged.
void restore(solve::Resumable& solver, const std::string& state, const std::filesystem::path& file);

}  // namespace hemirad::bake
