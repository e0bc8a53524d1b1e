# The image back-ends (src/image/image.h), chosen when an executable is linked:
#   hemirad_image            in hemirad_core: the codecs (libpng, libjpeg, libwebp, OpenEXR), which
#                            the codecs back-end is made of and both back-ends use (WebP, EXR reads)
#   hemirad_image_oiio       OpenImageIO decodes PNG and JPEG and writes the outputs (where found)
#   hemirad_image_codecs     the codecs do all of it (the relocatable bundle's: no OpenImageIO)
# HEMIRAD_IMAGE_BACKEND picks `hemirad`'s; the tests always link OpenImageIO's and compare the two.
set(HEMIRAD_IMAGE_BACKEND OpenImageIO CACHE STRING "The image back-end of hemirad: OpenImageIO or codecs")
set_property(CACHE HEMIRAD_IMAGE_BACKEND PROPERTY STRINGS OpenImageIO codecs)
if(NOT HEMIRAD_IMAGE_BACKEND MATCHES "^(OpenImageIO|codecs)$")
  message(FATAL_ERROR "HEMIRAD_IMAGE_BACKEND is '${HEMIRAD_IMAGE_BACKEND}': OpenImageIO or codecs")
endif()

find_package(PNG REQUIRED)
find_package(JPEG REQUIRED)
find_package(OpenEXR CONFIG REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(WEBP REQUIRED IMPORTED_TARGET libwebp)
# OpenImageIO: required by the full build's back-end and by the tests (they write their images
# with it, an implementation independent of hemirad's); not looked for otherwise.
if(HEMIRAD_IMAGE_BACKEND STREQUAL "OpenImageIO" OR HEMIRAD_BUILD_TESTS)
  find_package(OpenImageIO CONFIG REQUIRED)
endif()

add_library(hemirad_image STATIC
  ${PROJECT_SOURCE_DIR}/src/image/image.cpp ${PROJECT_SOURCE_DIR}/src/image/webp.cpp
  ${PROJECT_SOURCE_DIR}/src/image/codecs.cpp)
target_include_directories(hemirad_image PUBLIC ${PROJECT_SOURCE_DIR}/src)
target_compile_options(hemirad_image PRIVATE -Wall -Wextra -Wpedantic)
target_link_libraries(hemirad_image PUBLIC fmt::fmt PRIVATE PNG::PNG JPEG::JPEG PkgConfig::WEBP OpenEXR::OpenEXR)

add_library(hemirad_image_codecs OBJECT ${PROJECT_SOURCE_DIR}/src/image/use_codecs.cpp)
target_link_libraries(hemirad_image_codecs PUBLIC hemirad_image)
if(OpenImageIO_FOUND)
  add_library(hemirad_image_oiio OBJECT
    ${PROJECT_SOURCE_DIR}/src/image/use_oiio.cpp ${PROJECT_SOURCE_DIR}/src/image/oiio.cpp)
  target_link_libraries(hemirad_image_oiio PUBLIC hemirad_image OpenImageIO::OpenImageIO)
  target_compile_options(hemirad_image_oiio PRIVATE -Wall -Wextra -Wpedantic)
endif()
if(HEMIRAD_IMAGE_BACKEND STREQUAL "OpenImageIO")
  set(HEMIRAD_IMAGE oiio)
else()
  set(HEMIRAD_IMAGE codecs)
endif()
message(STATUS "hemirad: image back-end ${HEMIRAD_IMAGE_BACKEND}")

# `kind`: oiio or codecs. Every executable that links hemirad_core links one of them.
function(hemirad_use_image target kind)
  target_link_libraries(${target} PRIVATE hemirad_image_${kind})
endfunction()
