# ThreadSanitizer support for oneTBB (docs/reliability.md "ThreadSanitizer"), included by the
# top-level CMakeLists.txt after every target exists, only when ARTEX_SANITIZE has "thread":
# - TBB_USE_PROFILING_TOOLS=2 compiles oneTBB's header notifications (spawn, wait, partitioner);
# - artex_tsan_itt: the ITT collector libtbb loads (INTEL_LIBITTNOTIFY64) to report its own;
# - artex_tsan_tbb_pool: linked into every executable, annotates task memory reuse.
add_library(artex_tsan_itt SHARED ${PROJECT_SOURCE_DIR}/tests/tsan/tbb_itt_collector.cc)
add_library(artex_tsan_tbb_pool OBJECT ${PROJECT_SOURCE_DIR}/tests/tsan/tbb_pool_annotations.cc)
function(artex_tsan_link_executables dir)
  get_property(targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
  foreach(t IN LISTS targets)
    get_target_property(type ${t} TYPE)
    if(type STREQUAL "EXECUTABLE")
      target_link_libraries(${t} PRIVATE artex_tsan_tbb_pool ${CMAKE_DL_LIBS})
      add_dependencies(${t} artex_tsan_itt)
    endif()
  endforeach()
  get_property(subdirs DIRECTORY ${dir} PROPERTY SUBDIRECTORIES)
  foreach(d IN LISTS subdirs)
    artex_tsan_link_executables(${d})
  endforeach()
endfunction()
artex_tsan_link_executables(${PROJECT_SOURCE_DIR})
