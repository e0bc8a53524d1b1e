# Install rules, the relocatable bundle and the Debian package (scripts/package.sh drives them).
#
#   cmake --install build/release [--prefix P]   the full build in a standard layout: bin/hemirad,
#                                                 share/hemirad/scenes, share/doc/hemirad
#   component `bundle` (never part of a plain install): hemirad_bundle as bin/hemirad with the
#                                                 libraries it needs in lib/, found through an
#                                                 RPATH of $ORIGIN/../lib, so the folder runs
#                                                 from anywhere on a machine with only glibc,
#                                                 libstdc++ and an OpenCL driver
#   cpack -G DEB                                  the plain install under /usr as a .deb whose
#                                                 dependencies dpkg-shlibdeps reads off the binary
include(GNUInstallDirs)

install(TARGETS hemirad RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT hemirad)
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT hemirad)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/ DESTINATION ${CMAKE_INSTALL_DATADIR}/hemirad/scenes
        COMPONENT hemirad FILES_MATCHING PATTERN "*.gltf")

# The bundle's executable: the same libraries as `hemirad`, with the image back-end that needs
# only the format codecs (no OpenImageIO: its closure is ~350 MB) and one process (no MPI library;
# under mpirun it says so and stops). Built only when asked for (scripts/package.sh).
add_executable(hemirad_bundle EXCLUDE_FROM_ALL ${PROJECT_SOURCE_DIR}/src/cli/main.cpp)
target_link_libraries(hemirad_bundle PRIVATE hemirad_cli)
target_compile_options(hemirad_bundle PRIVATE -Wall -Wextra -Wpedantic)
hemirad_use_dist(hemirad_bundle single)
hemirad_use_image(hemirad_bundle codecs)
# DT_RPATH, not DT_RUNPATH: a RUNPATH serves only the executable's own dependencies, and the
# bundled libraries' dependencies (Embree's TBB, OpenEXR's Imath) must be found in lib/ too.
target_link_options(hemirad_bundle PRIVATE -Wl,--disable-new-dtags)
set_target_properties(hemirad_bundle PROPERTIES
  OUTPUT_NAME hemirad
  RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bundle/bin
  BUILD_WITH_INSTALL_RPATH ON
  INSTALL_RPATH "$ORIGIN/../lib")
install(TARGETS hemirad_bundle RUNTIME_DEPENDENCY_SET hemirad_bundle_libraries
        RUNTIME DESTINATION bin COMPONENT bundle EXCLUDE_FROM_ALL)
# Everything the loader resolves, except the C and C++ runtimes every Linux machine has (and whose
# copies must match the system's loader) and the OpenCL drivers, which the ICD loader (bundled)
# opens at run time from the machine's /etc/OpenCL/vendors.
install(RUNTIME_DEPENDENCY_SET hemirad_bundle_libraries
        DESTINATION lib COMPONENT bundle EXCLUDE_FROM_ALL
        PRE_EXCLUDE_REGEXES
          "^linux-vdso" "^ld-linux" "^libc\\.so" "^libm\\.so" "^libdl\\.so" "^libpthread\\.so" "^librt\\.so"
          "^libresolv\\.so" "^libutil\\.so" "^libanl\\.so"
          "^libstdc\\+\\+\\.so" "^libgcc_s\\.so")
install(FILES ${PROJECT_SOURCE_DIR}/packaging/README.bundle.md DESTINATION . RENAME README.md
        COMPONENT bundle EXCLUDE_FROM_ALL)
install(FILES ${PROJECT_SOURCE_DIR}/scripts/gpu-check.sh DESTINATION .
        PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE
        COMPONENT bundle EXCLUDE_FROM_ALL)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/ DESTINATION scenes COMPONENT bundle EXCLUDE_FROM_ALL
        FILES_MATCHING PATTERN "*.gltf")

# The Debian package: the plain install (not the bundle) under /usr.
set(CPACK_PACKAGE_NAME hemirad)
set(CPACK_PACKAGE_VENDOR "hemirad")
set(CPACK_PACKAGE_CONTACT "hemirad developers <hemirad@users.noreply.github.com>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "radiosity baker for glTF scenes with an OpenCL hemicube engine")
set(CPACK_PACKAGE_DESCRIPTION
    "hemirad bakes diffuse global illumination (radiosity) into glTF 2.0 scenes. Its form factors come from OpenCL hemicube kernels, run on the CPU through PoCL or on a GPU and checked against a scalar reference.")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_GENERATOR DEB)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # hemirad_<version>_amd64.deb
set(CPACK_DEBIAN_PACKAGE_SECTION graphics)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)   # Depends: from the libraries the binary links
# The ICD loader is a dependency through the binary; a device needs an OpenCL driver as well:
# PoCL runs the kernels on any CPU, a GPU vendor's driver provides the virtual opencl-icd.
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "pocl-opencl-icd | opencl-icd")

set(CPACK_OUTPUT_CONFIG_FILE ${PROJECT_BINARY_DIR}/CPackConfig.cmake)
include(CPack)
