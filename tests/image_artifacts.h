// Image comparisons that leave evidence: where two images differ, got.exr, reference.exr and
// difference.exr (the absolute difference, channel by channel) are written into a folder named
// after the test, under the build's test folder (tests/artifacts/) or $HEMIRAD_TEST_ARTIFACTS when
// set, and the failure message names them.
//
//     const test::ImageComparison c = test::compare_images(got, want);
//     INFO(c.message);
//     CHECK(c.same);
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "cli_support.h"

namespace hemirad::test {

// The folder for the current test's artifacts (not made here): $HEMIRAD_TEST_ARTIFACTS, else
// <build>/tests/artifacts, then the test's name with anything but letters, digits, '.', '-' and
// '_' as '_'.
std::filesystem::path artifact_dir();

struct ImageComparison {
    bool same = false;      // the same size, and every channel of every pixel within the tolerance
    long differing = 0;     // pixels with a channel off by more than the tolerance
    double worst = 0.0;     // the largest absolute difference of a channel
    std::vector<std::filesystem::path> files;  // got.exr, reference.exr, difference.exr, when written
    std::string message;    // what differs, and where the files went; empty when the same
};

// Compares the first three channels of `got` and `reference`, pixel by pixel; where they differ
// (in size, or by more than `tolerance` anywhere) writes the three images (artifact_dir()).
ImageComparison compare_images(const ImageData& got, const ImageData& reference, double tolerance = 0.0);

// For tests with an error measure of their own: writes got.exr, reference.exr and difference.exr
// from linear RGB (width × height × 3 each) and returns a line naming them.
std::string write_image_artifacts(const std::vector<float>& got_rgb, const std::vector<float>& reference_rgb,
                                  int width, int height);

}  // namespace hemirad::test
