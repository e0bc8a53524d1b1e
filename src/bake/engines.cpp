// The engine stack of a bake (see engines.h).
#include "bake/engines.h"

#include "formfactor/near_field.h"
#include "formfactor/unoccluded.h"
#include "solve/refinement.h"

namespace hemirad::bake {

std::unique_ptr<formfactor::Engine> observed(std::unique_ptr<formfactor::Engine> engine,
                                             const ObservedEngine::Observer& observer) {
    if (!observer) return engine;
    return std::make_unique<ObservedEngine>(std::move(engine), observer);
}

std::unique_ptr<formfactor::Engine> EngineStack::solve(const mesh::Mesh& mesh) {
    if (!occlusion_) return level(mesh, 0);
    std::unique_ptr<formfactor::Engine> engine =
        choice_.engine ? std::move(choice_.engine) : engine_like(choice_, mesh, settings_);
    return observed(std::make_unique<formfactor::NearFieldEngine>(mesh, std::move(engine)), on_shot_);
}

std::unique_ptr<formfactor::Engine> EngineStack::level(const mesh::Mesh& mesh, int level) const {
    if (!occlusion_) return observed(std::make_unique<formfactor::UnoccludedEngine>(mesh), on_shot_);
    formfactor::Settings s = settings_;
    s.hemicube = solve::regather_hemicube(settings_.hemicube, level);
    return observed(std::make_unique<formfactor::NearFieldEngine>(mesh, engine_like(choice_, mesh, s)), on_shot_);
}

std::unique_ptr<formfactor::Engine> EngineStack::gather(const mesh::Mesh& drawn, int hemicube) const {
    if (!occlusion_) return observed(std::make_unique<formfactor::UnoccludedEngine>(drawn), on_shot_);
    formfactor::Settings s = settings_;
    s.hemicube = hemicube;
    return observed(engine_like(choice_, drawn, s), on_shot_);
}

}  // namespace hemirad::bake
