# The instruction set artex is compiled for (docs/install.md, "Instruction set and Ceres").
# Included after ArtexDependencies (it needs to know how Ceres is linked). Sets
# ARTEX_ARCH_FLAGS (cache, internal): the flags every artex library passes on PUBLIC, so that
# its tests, tools, the Python module, the fuzz project and projects using the installed
# libraries compile alike.
#
# ARTEX_ARCH:
#   auto (default)  x86-64-v3 (AVX2, FMA: Eigen's products four doubles wide) when Ceres is linked
#                   as its shared library, the compiler accepts the flag and the build machine's
#                   CPU runs such code; else the compiler's default (plain x86-64, SSE2)
#   default         the compiler's default
#   other           -march=<value> (e.g. x86-64-v3, native)
# Any -march comes with -ffp-contract=off: the compiler fuses no multiply-add of artex's own
# code (Eigen's kernels still use FMA explicitly), so the code paths that tests compare bit for
# bit (e.g. the E-step's vector and scalar kernels) stay equal.
set(ARTEX_ARCH "auto" CACHE STRING
    "Instruction set: auto (x86-64-v3 where safe and supported), default, or a -march value")
include(CheckCXXSourceCompiles)
include(CheckCXXSourceRuns)

set(_artex_arch_flags)
if(ARTEX_ARCH STREQUAL "auto")
  if(ARTEX_CERES_IS_SHARED AND NOT CMAKE_CROSSCOMPILING)
    block(SCOPE_FOR VARIABLES PROPAGATE _artex_v3)
      set(CMAKE_REQUIRED_FLAGS "-march=x86-64-v3")
      set(CMAKE_REQUIRED_QUIET ON)
      # The program as one argument (adjacent quoted strings would be two: the check then
      # compiled half a program and every fresh configure fell back to plain x86-64).
      string(CONCAT _artex_v3_probe "int main() { __builtin_cpu_init(); "
             "return __builtin_cpu_supports(\"x86-64-v3\") ? 0 : 1; }")
      check_cxx_source_runs("${_artex_v3_probe}" ARTEX_HOST_RUNS_X86_64_V3)
      set(_artex_v3 ${ARTEX_HOST_RUNS_X86_64_V3})
    endblock()
    if(_artex_v3)
      set(_artex_arch_flags -march=x86-64-v3 -ffp-contract=off)
    endif()
  endif()
elseif(NOT ARTEX_ARCH STREQUAL "default")
  set(_artex_arch_flags -march=${ARTEX_ARCH} -ffp-contract=off)
  block()
    string(JOIN " " CMAKE_REQUIRED_FLAGS ${_artex_arch_flags})
    set(CMAKE_REQUIRED_QUIET ON)
    unset(ARTEX_ARCH_COMPILES CACHE)
    check_cxx_source_compiles("int main() { return 0; }" ARTEX_ARCH_COMPILES)
  endblock()
  if(NOT ARTEX_ARCH_COMPILES)
    message(FATAL_ERROR "artex: ARTEX_ARCH: expected auto, default or a -march value that "
                        "${CMAKE_CXX_COMPILER} accepts (e.g. x86-64-v3, native), found "
                        "\"${ARTEX_ARCH}\" (-march=${ARTEX_ARCH} does not compile)")
  endif()
endif()
set(ARTEX_ARCH_FLAGS "${_artex_arch_flags}" CACHE INTERNAL "artex's instruction-set flags")
if(_artex_arch_flags)
  message(STATUS "artex: compiling for ${_artex_arch_flags} (ARTEX_ARCH=${ARTEX_ARCH})")
else()
  message(STATUS "artex: compiling for the compiler's default instruction set "
                 "(ARTEX_ARCH=${ARTEX_ARCH})")
endif()

# With the static libceres.a (compiled for plain x86-64), flags that make Eigen use AVX are
# refused: the library shares Eigen's inline code with artex at link time, and Eigen compiled for
# AVX allocates its matrices differently (docs/install.md, "Instruction set and Ceres").
# ARTEX_ALLOW_AVX_EIGEN=ON overrides, e.g. with a Ceres built alike.
option(ARTEX_ALLOW_AVX_EIGEN "Build even when Eigen would use AVX and Ceres is static" OFF)
if(NOT ARTEX_CERES_IS_SHARED AND NOT ARTEX_ALLOW_AVX_EIGEN)
  string(TOUPPER "${CMAKE_BUILD_TYPE}" _artex_config)
  string(JOIN " " _artex_flags ${CMAKE_CXX_FLAGS} ${CMAKE_CXX_FLAGS_${_artex_config}}
         ${_artex_arch_flags})
  block()  # the check compiles with the build type's flags too
    set(CMAKE_TRY_COMPILE_CONFIGURATION "${CMAKE_BUILD_TYPE}")
    string(JOIN " " CMAKE_REQUIRED_FLAGS ${_artex_arch_flags})
    unset(ARTEX_FLAGS_KEEP_EIGEN_OFF_AVX CACHE)
    check_cxx_source_compiles("#ifdef __AVX__\n#error AVX\n#endif\nint main() { return 0; }"
                              ARTEX_FLAGS_KEEP_EIGEN_OFF_AVX)
  endblock()
  if(NOT ARTEX_FLAGS_KEEP_EIGEN_OFF_AVX)
    message(FATAL_ERROR
            "artex: the compiler flags (\"${_artex_flags}\") compile for AVX, so Eigen would use "
            "32-byte alignment and its own allocator, while the static libceres.a, compiled for "
            "plain x86-64, uses glibc's malloc for the same functions: the heap gets corrupted "
            "when a matrix crosses between the two (docs/install.md, \"Instruction set and "
            "Ceres\"). Link Ceres's shared library (-DARTEX_CERES_SHARED=ON, the default, "
            "where libceres.so exists), remove -march/-mavx* from CMAKE_CXX_FLAGS, "
            "CMAKE_CXX_FLAGS_<build type> and ARTEX_ARCH, or set -DARTEX_ALLOW_AVX_EIGEN=ON with "
            "a Ceres compiled with the same flags.")
  endif()
endif()
