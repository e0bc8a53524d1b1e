// hemirad executable entry point; all logic lives in cli/app.cpp.
#include <malloc.h>

#include "cli/app.h"

int main(int argc, char** argv) {
    // Blocks of 1 MiB and more are mapped and unmapped on their own, always. glibc raises that
    // threshold by itself to the size of the largest such block freed (up to 32 MiB), after which
    // buffers of that size stay in the heap once freed: each refinement level's engine is larger
    // than the last, and the Cornell box's bake peaked at 313–318 MB that way, 299–305 MB without.
    mallopt(M_MMAP_THRESHOLD, 1 << 20);
    return hemirad::cli::run(argc, argv);
}
