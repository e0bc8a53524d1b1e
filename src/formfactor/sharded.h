// ShardedEngine: one engine over several, each on its own device (or MPI rank: dist/dist.h),
// sharing every batch. A batch is cut into chunks that the members take as they finish their
// last, one host thread each (dynamic, guided scheduling: a fast GPU takes more than a CPU). A
// shot's row depends on the shot alone, never on who computed it or what else was in its batch
// (every engine gives the reference's bits), so the rows are those of any one member.
//
// A member marked `may_drop` (a device that `auto` or `all` chose) that fails leaves the bake:
// its chunk goes back to the others and the rows stay the same; a member that may not drop, or
// the last one, ends the batch with its exception.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "formfactor/engine.h"

namespace hemirad::formfactor {

// Per member, what it did over the engine's life (shared between the engines a bake makes for
// its refined meshes, so that report.json sums them).
struct ShardStats {
    struct Member {
        std::string id;        // "opencl:0.1", "ref", "rank 2"
        long shots = 0;        // rows it computed
        long chunks = 0;
        double seconds = 0.0;  // in its shoot_batch calls
        std::string dropped;   // why it left the bake; empty while it is in
    };
    std::mutex mutex;
    std::vector<Member> members;
};

class ShardedEngine final : public Engine {
public:
    struct Member {
        std::unique_ptr<Engine> engine;
        std::string id;
        bool may_drop = false;
    };
    // `failure`: the one-line reason when an exception is the device's failure (then a member
    // that may drop leaves); empty for any other (a bug or bad input: rethrown at once). `stats`
    // (optional) must list the members in the same order, by id.
    ShardedEngine(std::vector<Member> members, std::function<std::string(const std::exception&)> failure,
                  std::shared_ptr<ShardStats> stats = nullptr);
    ~ShardedEngine() override;

    std::string name() const override;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;

    // The live members' together.
    std::size_t preferred_batch() const override;
    std::size_t members() const { return slots_.size(); }
    std::size_t live() const;
    // A member takes 1 / (kShareOfRest × live members) of the shots left (at least one): the
    // first chunks are large, the last single shots, so that a fast member takes more and all
    // finish together.
    static constexpr std::size_t kShareOfRest = 2;

private:
    struct Slot {
        Member member;
        bool live = true;
    };
    std::vector<Slot> slots_;
    std::function<std::string(const std::exception&)> failure_;
    std::shared_ptr<ShardStats> stats_;
    std::vector<ShotResult> one_;

    void record(std::size_t slot, long shots, double seconds, const std::string& dropped);
};

}  // namespace hemirad::formfactor
