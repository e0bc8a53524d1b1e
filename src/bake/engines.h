// The engine stack of a bake, made in one place for the bake and the benchmarks: the chosen
// device's engine (verified, sharded among devices and ranks: engine_select.h), the near-field
// correction, and an observer of every shot; or exact unoccluded form factors where nothing hides
// anything.
#pragma once

#include <functional>
#include <memory>

#include "bake/engine_select.h"
#include "formfactor/engine.h"
#include "mesh/mesh.h"

namespace hemirad::bake {

// Shows every shot of the engine it wraps to an observer (Options::on_shot).
class ObservedEngine final : public formfactor::Engine {
public:
    using Observer = std::function<void(const formfactor::ShotResult&)>;
    ObservedEngine(std::unique_ptr<formfactor::Engine> inner, Observer observer)
        : inner_(std::move(inner)), observer_(std::move(observer)) {}
    std::string name() const override { return inner_->name(); }
    using formfactor::Engine::shoot;
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        inner_->shoot(request, out);
        observer_(out);
    }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots,
                     std::vector<formfactor::ShotResult>& out) override {
        inner_->shoot_batch(shots, out);
        for (const formfactor::ShotResult& r : out) observer_(r);
    }
    const std::vector<std::int32_t>* last_ids(std::size_t i) const override { return inner_->last_ids(i); }
    std::size_t preferred_batch() const override { return inner_->preferred_batch(); }

private:
    std::unique_ptr<formfactor::Engine> inner_;
    Observer observer_;
};

// `engine` wrapped to show its shots to `observer` (unwrapped where there is none).
std::unique_ptr<formfactor::Engine> observed(std::unique_ptr<formfactor::Engine> engine,
                                             const ObservedEngine::Observer& observer);

// Makes every engine a bake uses, of the kind `choice` names.
class EngineStack {
public:
    // `occlusion` off: exact unoccluded form factors (no hemicube, `choice` unused).
    EngineStack(EngineChoice& choice, const formfactor::Settings& settings, bool occlusion,
                ObservedEngine::Observer on_shot)
        : choice_(choice), settings_(settings), occlusion_(occlusion), on_shot_(std::move(on_shot)) {}

    // The solve's engine on the base mesh: the choice's own (its devices already hold `mesh`),
    // or where it was taken (a benchmark's later runs) one like it.
    std::unique_ptr<formfactor::Engine> solve(const mesh::Mesh& mesh);
    // An engine for a refined mesh at `level` (0: the base): the hemicube's resolution rises with
    // the level, so that children cover as many cells as their parents did.
    std::unique_ptr<formfactor::Engine> level(const mesh::Mesh& mesh, int level) const;
    // The final gather's engine on its drawn mesh (solve::gather_mesh), at hemicube N `hemicube`.
    std::unique_ptr<formfactor::Engine> gather(const mesh::Mesh& drawn, int hemicube) const;

    const EngineChoice& choice() const { return choice_; }
    const formfactor::Settings& settings() const { return settings_; }
    bool occlusion() const { return occlusion_; }

private:
    EngineChoice& choice_;
    formfactor::Settings settings_;
    bool occlusion_;
    ObservedEngine::Observer on_shot_;
};

}  // namespace hemirad::bake
