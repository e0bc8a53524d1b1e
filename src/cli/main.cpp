// hemirad executable entry point; all logic lives in cli/app.cpp.
#include "cli/app.h"

int main(int argc, char** argv) { return hemirad::cli::run(argc, argv); }
