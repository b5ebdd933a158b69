# Third-party dependencies, all from Debian 12 packages (see scripts/setup).
find_package(Threads REQUIRED)
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(Ceres 2.1 REQUIRED)
# Ceres as its shared library where Debian ships one (cmake/ArtexCeresShared.cmake): artex's
# Eigen code then never mixes with the static library's, which allows an AVX2 build
# (cmake/ArtexArch.cmake). OFF: the static libceres.a that Ceres's package names.
option(ARTEX_CERES_SHARED "Link Ceres's shared library (libceres.so) where present" ON)
include(ArtexCeresShared)
set(ARTEX_CERES_IS_SHARED OFF)
if(ARTEX_CERES_SHARED)
  artex_use_shared_ceres()
endif()
# imgcodecs for the tests only: artex reads and writes PNG and JPEG through libpng and libjpeg-turbo
# (sensors/image_codec.h), since imgcodecs loads GDAL and ~100 more libraries at every start.
find_package(OpenCV 4.6 REQUIRED COMPONENTS core imgproc imgcodecs)
find_package(PNG 1.6 REQUIRED)
find_package(JPEG REQUIRED)
find_package(ZLIB REQUIRED)
find_package(OpenMesh REQUIRED CONFIG)
find_package(nanoflann 1.4 REQUIRED)
find_package(yaml-cpp 0.7 REQUIRED)
find_package(nlohmann_json 3.11 REQUIRED)
find_package(CLI11 2.1 REQUIRED)
find_package(TBB 2021 REQUIRED)
find_package(TinyGLTF REQUIRED CONFIG)
find_package(PkgConfig REQUIRED)
pkg_check_modules(MAXFLOW REQUIRED IMPORTED_TARGET maxflow)
# PNG frames are inflated by libdeflate (libdeflate-dev; sensors/png_decode.h).
pkg_check_modules(ARTEX_LIBDEFLATE REQUIRED IMPORTED_TARGET libdeflate)
if(ARTEX_BUILD_TESTS)
  find_package(GTest 1.12 REQUIRED CONFIG)
endif()
if(ARTEX_BUILD_BENCH)
  find_package(benchmark 1.7 REQUIRED)
endif()
