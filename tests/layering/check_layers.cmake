# Checks the include walls of docs/architecture.md on every source file:
#  - a plugin (plugins/<name>/) includes no engine or internal header, and no header of another
#    plugin's folder (a quoted include must name a file of its own folder);
#  - the SDK library includes nothing above it (geometry, kernels, engine); geometry and kernels
#    include no engine header;
#  - no CMake file adds another layer's private src/ folder to an include path.
# Prints one line per crossing, "FILE:LINE: what", and fails when there is any.
cmake_minimum_required(VERSION 3.22)
if(NOT DEFINED SOURCE_DIR)
  message(FATAL_ERROR "check_layers.cmake: SOURCE_DIR not set")
endif()

set(crossings "")
# forbid(GLOB_ROOT REGEX WHAT): every C++ file below GLOB_ROOT whose include line matches REGEX.
function(forbid root regex what)
  file(GLOB_RECURSE files ${SOURCE_DIR}/${root}/*.h ${SOURCE_DIR}/${root}/*.cpp)
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include")
    foreach(l ${lines})
      if(l MATCHES "${regex}")
        file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
        list(APPEND crossings "${rel}: ${what}: ${l}")
      endif()
    endforeach()
  endforeach()
  set(crossings "${crossings}" PARENT_SCOPE)
endfunction()

forbid(plugins "<deform/(engine|internal)/" "a plugin includes an engine or internal header")
forbid(plugins "deform_harness/" "a plugin includes a harness header")
# The SDK library (its back end in sdk/contact_bullet/ is loaded, never linked, and may use geometry).
forbid(core/sdk/include "<deform/(geometry|kernels|engine)/" "the SDK includes a header above it")
forbid(core/sdk/src "<deform/(geometry|kernels|engine)/" "the SDK includes a header above it")
forbid(core/geometry "<deform/engine/" "geometry includes an engine header")
forbid(core/kernels "<deform/(engine|geometry)/" "kernels include an engine or geometry header")

# Quoted includes in a plugin name a file of the plugin's own folder.
file(GLOB plugin_dirs LIST_DIRECTORIES true ${SOURCE_DIR}/plugins/*)
foreach(dir ${plugin_dirs})
  if(NOT IS_DIRECTORY ${dir})
    continue()
  endif()
  file(GLOB_RECURSE files ${dir}/*.h ${dir}/*.cpp)
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    get_filename_component(here ${f} DIRECTORY)
    foreach(l ${lines})
      string(REGEX REPLACE "^[^\"]*\"([^\"]*)\".*$" "\\1" inc "${l}")
      if(NOT EXISTS ${here}/${inc} OR inc MATCHES "\\.\\.")
        file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
        list(APPEND crossings "${rel}: a quoted include outside the plugin's folder: ${l}")
      endif()
    endforeach()
  endforeach()
endforeach()

file(GLOB_RECURSE cmake_files ${SOURCE_DIR}/core/CMakeLists.txt ${SOURCE_DIR}/core/*/CMakeLists.txt
  ${SOURCE_DIR}/plugins/*/CMakeLists.txt ${SOURCE_DIR}/harness/CMakeLists.txt)
foreach(f ${cmake_files})
  file(STRINGS ${f} lines REGEX "\\.\\./[a-z]+/src")
  foreach(l ${lines})
    file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
    list(APPEND crossings "${rel}: another layer's src/ on an include path: ${l}")
  endforeach()
endforeach()

list(LENGTH crossings n)
if(n GREATER 0)
  list(JOIN crossings "\n" text)
  message(FATAL_ERROR "${n} layer crossing(s):\n${text}")
endif()
message(STATUS "layering: no crossings")
