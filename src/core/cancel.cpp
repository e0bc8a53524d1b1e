// The stop flag, the signal handler that sets it, and the watchdog that makes a stop prompt.
#include "core/cancel.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace hemirad::cancel {
namespace fs = std::filesystem;

struct Cleanup::State {
    std::vector<fs::path> trees, files, empty_dirs;
    std::atomic<bool> released{false};
};

namespace {

std::atomic<bool> g_reported{false};
std::atomic<int> g_signal{0};  // the first signal that asked for a stop; lock-free (static_assert below)
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler may only touch a lock-free atomic");

// The scopes alive, and the mutex that orders the watchdog's clean-up against their changes and
// commits. Never destroyed: the watchdog may still run while static destructors do.
struct Registry {
    std::recursive_mutex mutex;  // a critical() section may register paths
    std::vector<std::weak_ptr<Cleanup::State>> scopes;
};
Registry& registry() {
    static Registry* r = new Registry;
    return *r;
}

// The signals that would end the process by default and that a handler can catch (SIGKILL and
// SIGSTOP cannot be; SIGSEGV and the like are faults, not requests).
constexpr int kInterrupts[] = {SIGINT, SIGTERM, SIGHUP};
constexpr int kOthers[] = {SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF, SIGXCPU, SIGXFSZ, SIGPIPE};

extern "C" void on_signal(int signal) {
    int none = 0;
    g_signal.compare_exchange_strong(none, signal);  // the first one decides the exit code
}

const char* signal_name(int signal) {
    switch (signal) {
        case SIGQUIT: return "SIGQUIT";
        case SIGUSR1: return "SIGUSR1";
        case SIGUSR2: return "SIGUSR2";
        case SIGALRM: return "SIGALRM";
        case SIGVTALRM: return "SIGVTALRM";
        case SIGPROF: return "SIGPROF";
        case SIGXCPU: return "SIGXCPU";
        case SIGXFSZ: return "SIGXFSZ";
        case SIGPIPE: return "SIGPIPE";
        default: return "a signal";
    }
}

// Removes what one scope holds (the registry's mutex held).
void remove_all_of(const Cleanup::State& s) {
    std::error_code ec;
    for (const fs::path& f : s.files) fs::remove(f, ec);
    for (const fs::path& t : s.trees) fs::remove_all(t, ec);
    // Deepest first (a preview directory inside a directory the bake made); only if empty.
    std::vector<fs::path> dirs = s.empty_dirs;
    std::stable_sort(dirs.begin(), dirs.end(), [](const fs::path& a, const fs::path& b) {
        return std::distance(a.begin(), a.end()) > std::distance(b.begin(), b.end());
    });
    for (const fs::path& d : dirs) fs::remove(d, ec);
}

// Removes what every live, unreleased scope holds. Returns whether any scope was released (the
// outputs are committed: the process is to finish by itself).
bool clean_up_all() {
    Registry& r = registry();
    std::lock_guard<std::recursive_mutex> lock(r.mutex);
    bool committed = false;
    for (const std::weak_ptr<Cleanup::State>& weak : r.scopes) {
        const std::shared_ptr<Cleanup::State> s = weak.lock();
        if (!s) continue;
        if (s->released)
            committed = true;
        else
            remove_all_of(*s);
    }
    return committed;
}

// The signals install() took (not those the process started with ignored).
std::vector<int>& owned() {
    static std::vector<int>* signals = new std::vector<int>;
    return *signals;
}

void take(int signal) {
    struct sigaction action {};
    action.sa_handler = on_signal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    sigaction(signal, &action, nullptr);
}

// Scopes hold absolute paths: deepest first is then by components, whatever the owner named.
fs::path absolute_path(const fs::path& p) {
    std::error_code ec;
    const fs::path a = fs::absolute(p, ec);
    return ec ? p : a;
}

void watchdog() {
    using namespace std::chrono;
    while (g_signal.load() == 0) {
        std::this_thread::sleep_for(milliseconds(10));
        // Libraries loaded later take signals for themselves: LLVM, inside PoCL's kernel compiler,
        // keeps SIGUSR1 (and so deafens the process to it), and puts its own handler before ours
        // for the others. Ours again, wherever another has replaced it.
        for (const int s : owned()) {
            struct sigaction current {};
            if (sigaction(s, nullptr, &current) == 0 && current.sa_handler != on_signal) take(s);
        }
    }
    // SIGXCPU comes a second before the kernel's SIGKILL (a CPU-time limit): no grace.
    if (g_signal.load() != SIGXCPU) std::this_thread::sleep_for(duration<double>(kGraceSeconds));
    if (clean_up_all()) return;  // committed: the bake is finishing
    if (!g_reported.load()) {
        const std::string line = "hemirad: " + describe() + "; no output written\n";
        [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, line.data(), line.size());
    }
    ::_exit(exit_code());
}

}  // namespace

void install() {
    static std::once_flag once;
    std::call_once(once, [] {
        registry();  // made before any signal can arrive
        owned();
        const auto handle = [](int signal) {
            struct sigaction old {};
            if (sigaction(signal, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) return;  // nohup, background jobs
            owned().push_back(signal);
            take(signal);
        };
        for (const int s : kInterrupts) handle(s);
        for (const int s : kOthers) handle(s);
        std::thread(watchdog).detach();
    });
}

bool requested() { return g_signal.load(std::memory_order_relaxed) != 0; }

int signal_number() { return g_signal.load(); }

int exit_code() {
    const int s = g_signal.load();
    return std::find(std::begin(kInterrupts), std::end(kInterrupts), s) != std::end(kInterrupts) ? 130 : 128 + s;
}

std::string describe() {
    const int s = g_signal.load();
    if (s == 0 || std::find(std::begin(kInterrupts), std::end(kInterrupts), s) != std::end(kInterrupts))
        return "interrupted";
    return std::string("stopped by ") + signal_name(s);
}

void reported() { g_reported.store(true); }

void check() {
    if (requested()) throw Interrupted();
}

void request_for_test(int signal) { g_signal.store(signal); }
void reset_for_test() { g_signal.store(0); }

Cleanup::Cleanup() : state_(std::make_shared<State>()) {
    Registry& r = registry();
    std::lock_guard<std::recursive_mutex> lock(r.mutex);
    r.scopes.erase(std::remove_if(r.scopes.begin(), r.scopes.end(),
                                  [](const std::weak_ptr<State>& w) { return w.expired(); }),
                   r.scopes.end());
    r.scopes.push_back(state_);
}

Cleanup::~Cleanup() {
    std::lock_guard<std::recursive_mutex> lock(registry().mutex);
    state_.reset();  // the registry's weak pointer expires with it
}

void Cleanup::remove_tree(const fs::path& path) {
    std::lock_guard<std::recursive_mutex> lock(registry().mutex);
    state_->trees.push_back(absolute_path(path));
}

void Cleanup::remove_file(const fs::path& path) {
    std::lock_guard<std::recursive_mutex> lock(registry().mutex);
    state_->files.push_back(absolute_path(path));
}

void Cleanup::remove_if_empty(const fs::path& dir) {
    std::lock_guard<std::recursive_mutex> lock(registry().mutex);
    state_->empty_dirs.push_back(absolute_path(dir));
}

void Cleanup::release() { state_->released = true; }  // atomic: inside critical() or alone

void Cleanup::remove_now() {
    std::lock_guard<std::recursive_mutex> lock(registry().mutex);
    if (!state_->released) remove_all_of(*state_);
}

Cleanup::Lock::Lock(Cleanup&) { registry().mutex.lock(); }
Cleanup::Lock::~Lock() { registry().mutex.unlock(); }

}  // namespace hemirad::cancel
