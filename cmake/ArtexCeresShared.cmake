# artex_use_shared_ceres(): point the imported target Ceres::ceres at Debian's shared
# libceres.so instead of the static libceres.a that Ceres's CMake package names (both come from
# the same build, in libceres-dev and libceres3). Sets ARTEX_CERES_IS_SHARED in the caller's
# scope: ON when Ceres::ceres now names a shared library.
#
# Why (docs/install.md, "Instruction set and Ceres"): the static library brings its own copies
# of Eigen's inline functions, which the linker merges with artex's; compiled for other
# instruction sets the two copies allocate matrices differently and corrupt the heap. The shared
# library exports none of Eigen's functions (only Ceres's own API, which passes raw pointers),
# so artex may then compile Eigen for AVX2 whatever Ceres was compiled for. Included by the main
# project, the fuzz project and the installed artexConfig.cmake, so that all of them link Ceres
# the same way.
function(artex_use_shared_ceres)
  set(ARTEX_CERES_IS_SHARED OFF PARENT_SCOPE)
  if(NOT TARGET Ceres::ceres)
    return()
  endif()
  get_target_property(type Ceres::ceres TYPE)
  if(type STREQUAL "SHARED_LIBRARY")
    set(ARTEX_CERES_IS_SHARED ON PARENT_SCOPE)
    return()
  endif()
  get_target_property(configs Ceres::ceres IMPORTED_CONFIGURATIONS)
  if(NOT configs)
    return()
  endif()
  set(locations)
  foreach(config IN LISTS configs)
    get_target_property(location Ceres::ceres IMPORTED_LOCATION_${config})
    if(NOT location MATCHES "\\.a$")
      return()
    endif()
    string(REGEX REPLACE "\\.a$" ".so" shared "${location}")
    if(NOT EXISTS "${shared}")
      return()
    endif()
    list(APPEND locations ${config} "${shared}")
  endforeach()
  while(locations)
    list(POP_FRONT locations config shared)
    set_property(TARGET Ceres::ceres PROPERTY IMPORTED_LOCATION_${config} "${shared}")
  endwhile()
  set(ARTEX_CERES_IS_SHARED ON PARENT_SCOPE)
endfunction()
