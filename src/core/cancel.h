// Stopping a bake when asked: the signals that end it, the checks its long loops make, and a
// watchdog that cleans up and exits within a second wherever the bake is (inside a kernel build,
// a single long launch, a library call that polls nothing).
//
// A caught signal only sets a flag (all a handler may safely do). The bake's loops call check(),
// which throws Interrupted; the bake unwinds, its destructors remove what it wrote, and the CLI
// exits with exit_code(). Should it not have exited kGraceSeconds after the signal, the watchdog
// thread removes the paths registered in Cleanup scopes itself, prints the same line, and ends
// the process with _exit(exit_code()).
#pragma once

#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

namespace hemirad::cancel {

// Thrown by check() once a stop was asked for; nothing the bake wrote is left (its scopes go).
struct Interrupted : std::runtime_error {
    Interrupted() : std::runtime_error("interrupted") {}
};

// How long the watchdog leaves the bake to unwind by itself (a pass, a batch of shots).
constexpr double kGraceSeconds = 0.5;

// Installs the handler for every signal that would end the process and can be caught: SIGINT,
// SIGTERM, SIGHUP (exit 130, "interrupted"), and SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM,
// SIGPROF, SIGXCPU, SIGXFSZ, SIGPIPE (exit 128 + the signal). A signal the process was started
// with ignored stays ignored (nohup's SIGHUP, a background job's SIGINT). Starts the watchdog.
// Idempotent.
void install();

// Whether a stop was asked for, and by which signal (0: none).
bool requested();
int signal_number();
// 130 for SIGINT, SIGTERM and SIGHUP (README, exit codes), 128 + the signal for the others.
int exit_code();
// The line the CLI prints: "interrupted" or "stopped by SIGQUIT".
std::string describe();

// The CLI has printed the line itself: the watchdog, should it still act, prints nothing.
void reported();

// Throws Interrupted when a stop was asked for. Cheap (one relaxed load): call it in long loops.
void check();

// For tests: asks for a stop as if `signal` had arrived, or clears it.
void request_for_test(int signal);
void reset_for_test();

// Paths that a failed or interrupted bake must not leave behind, for the watchdog. The owner
// removes them itself when it unwinds (its destructor); the scope only tells the watchdog what
// to remove when the owner cannot. Thread-safe. `release()` once the paths are the user's (the
// outputs were committed): from then on the watchdog removes nothing of this scope and leaves
// the process to finish.
class Cleanup {
public:
    Cleanup();
    ~Cleanup();
    Cleanup(const Cleanup&) = delete;
    Cleanup& operator=(const Cleanup&) = delete;
    void remove_tree(const std::filesystem::path& path);    // a directory and all in it
    void remove_file(const std::filesystem::path& path);    // a file
    void remove_if_empty(const std::filesystem::path& dir);  // a directory, only if empty (after the rest)
    // Runs `f` while the watchdog cannot clean up (a commit's renames, a preview frame): it waits
    // for `f`, which may register paths.
    template <class F>
    void critical(F&& f) {
        Lock lock(*this);
        f();
    }
    void release();  // committed: nothing to remove
    // Removes what the scope holds now, as the watchdog would (files, trees, then the empty
    // directories deepest first), unless released: the owner's own clean-up when it unwinds.
    void remove_now();

    struct State;  // what the watchdog reads (cancel.cpp)

private:
    struct Lock {
        explicit Lock(Cleanup&);
        ~Lock();
    };
    std::shared_ptr<State> state_;
};

}  // namespace hemirad::cancel
