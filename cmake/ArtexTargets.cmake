include(GNUInstallDirs)

# Helpers shared by every module: warnings per target, never global flags.
function(artex_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wno-unused-parameter
                         -Wno-deprecated-declarations)
endfunction()

# artex_add_library(NAME name SOURCES ... DEPS ...): library artex_<name>, alias artex::<name>;
# installed with its headers (include/artex/<name>/*.h) and exported as artex::<name>
# (cmake/artexConfig.cmake.in).
function(artex_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(artex_${ARG_NAME} STATIC ${ARG_SOURCES})
  add_library(artex::${ARG_NAME} ALIAS artex_${ARG_NAME})
  set_target_properties(artex_${ARG_NAME} PROPERTIES EXPORT_NAME ${ARG_NAME})
  target_include_directories(artex_${ARG_NAME} PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
                             $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/artex>)
  install(TARGETS artex_${ARG_NAME} EXPORT artexTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT devel)
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/artex/${ARG_NAME}
          COMPONENT devel FILES_MATCHING PATTERN "*.h")
  target_link_libraries(artex_${ARG_NAME} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  # The instruction set (cmake/ArtexArch.cmake), passed on: whatever includes artex's headers
  # must compile Eigen alike, or its matrices are allocated one way and freed another.
  target_compile_options(artex_${ARG_NAME} PUBLIC ${ARTEX_ARCH_FLAGS})
  if(ARTEX_SANITIZE)
    # An installed sanitizer build needs its runtime in every executable that links it (inside
    # this project the global link option of CMakeLists.txt does that).
    target_link_options(artex_${ARG_NAME} INTERFACE
                        $<INSTALL_INTERFACE:-fsanitize=${ARTEX_SANITIZE}>)
  endif()
  artex_set_warnings(artex_${ARG_NAME})
endfunction()
