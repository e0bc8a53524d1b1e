// The checks that keep NaN and Inf out of every output of a bake.
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>

#include "output/finite.h"

using namespace hemirad;

TEST_CASE("finite: the first NaN or Inf of a report is found by its JSON pointer", "[output]") {
    nlohmann::ordered_json report = {{"passes", 12},
                                     {"energy", {{"emitted", 1.5}, {"absorbed", 1.2}}},
                                     {"meshes", nlohmann::ordered_json::array({{{"radiosity", {0.1, 0.2, 0.3}}}})}};
    CHECK(output::first_non_finite(report).empty());
    report["energy"]["absorbed"] = std::numeric_limits<double>::quiet_NaN();
    CHECK(output::first_non_finite(report) == "/energy/absorbed");
    report["energy"]["absorbed"] = 1.2;
    report["meshes"][0]["radiosity"][2] = std::numeric_limits<double>::infinity();
    CHECK(output::first_non_finite(report) == "/meshes/0/radiosity/2");
    CHECK(output::first_non_finite(nlohmann::ordered_json(-std::numeric_limits<double>::infinity())) == "/");
}

TEST_CASE("finite: images and radiosity with a NaN or Inf are caught", "[output]") {
    output::Image image;
    image.width = 2;
    image.height = 1;
    image.rgb = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f};
    CHECK(output::all_finite(image));
    image.rgb[4] = std::numeric_limits<float>::quiet_NaN();
    CHECK_FALSE(output::all_finite(image));
    std::vector<glm::dvec3> radiosity = {glm::dvec3(1.0), glm::dvec3(2.0)};
    CHECK(output::all_finite(radiosity));
    radiosity[1].y = std::numeric_limits<double>::infinity();
    CHECK_FALSE(output::all_finite(radiosity));
}
