# Helpers shared by every module: warnings per target, never global flags.
function(artex_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wno-unused-parameter
                         -Wno-deprecated-declarations)
endfunction()

# artex_add_library(NAME name SOURCES ... DEPS ...): library artex_<name>, alias artex::<name>.
function(artex_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(artex_${ARG_NAME} STATIC ${ARG_SOURCES})
  add_library(artex::${ARG_NAME} ALIAS artex_${ARG_NAME})
  target_include_directories(artex_${ARG_NAME} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(artex_${ARG_NAME} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  artex_set_warnings(artex_${ARG_NAME})
endfunction()
