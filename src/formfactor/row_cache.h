// A memo of form-factor rows for any engine. A shot is a pure function of its request (the
// shooter and the shot counter, which fixes the hemicube's rotation): every engine gives the same
// row for the same request, alone or in any batch. So a request seen before need not be shot
// again. The progressive solver asks for a patch's later shots under the counters of its first
// few (solve::Progressive), so that light trapped between a few patches (the inside of a lamp
// shade of reflectance 0.9999) is shot on from rows already made instead of new hemicubes.
//
// A row is kept when its shooter has been asked for before (under any counter): most patches
// shoot once or twice, and the memory goes to those that come back again and again. Rows are
// dropped least recently used first once they pass the budget; a row not kept, or dropped, that
// is asked for again is shot again, to the same bits. The rows a bake gets are therefore the same
// whatever the budget: it decides only how many are shot more than once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <unordered_map>
#include <vector>

#include "formfactor/engine.h"

namespace hemirad::formfactor {

struct RowCacheStats {
    long requests = 0;      // shots asked for
    long hits = 0;          // answered from a kept row
    long shot = 0;          // the others, shot by the engine
    long kept = 0;          // rows stored (some dropped again)
    long dropped = 0;       // rows dropped for the budget
    double peak_bytes = 0;  // the most the kept rows held at once
    double budget_bytes = 0;
};

class RowCacheEngine final : public Engine {
public:
    RowCacheEngine(std::unique_ptr<Engine> inner, double budget_bytes);
    std::string name() const override { return inner_->name(); }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;
    // The id buffer of shot i of the last batch where the inner engine shot it; nullptr for a
    // row that came from the memo.
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override;
    std::size_t preferred_batch() const override { return inner_->preferred_batch(); }

    const RowCacheStats& stats() const { return stats_; }
    // Bytes a kept row takes: its entries, and the bookkeeping around them.
    static double row_bytes(const ShotResult& row);

private:
    struct Key {
        Shooter::Kind kind;
        std::uint32_t patch;
        std::uint64_t shot;
        bool operator==(const Key& o) const { return kind == o.kind && patch == o.patch && shot == o.shot; }
    };
    struct KeyHash {
        std::size_t operator()(const Key& k) const;
    };
    struct Row {
        ShotResult result;
        std::list<Key>::iterator use;  // its place in use_, most recent first
    };
    static Key key_of(const ShotRequest& r) { return {r.shooter.kind, r.shooter.patch, r.shot}; }
    void keep(const Key& key, const ShotResult& row);

    std::unique_ptr<Engine> inner_;
    std::unordered_map<Key, Row, KeyHash> rows_;
    std::list<Key> use_;
    double bytes_ = 0.0;
    RowCacheStats stats_;
    std::vector<bool> seen_;  // per patch: asked for before
    std::vector<long> inner_index_;  // per shot of the last batch: its index in the inner batch, or −1
    std::vector<ShotRequest> misses_;
    std::vector<ShotResult> shot_;
};

}  // namespace hemirad::formfactor
