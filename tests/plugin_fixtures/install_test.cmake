# cmake -P script run by CTest (test plugin_sdk_install_export):
#  1. install the SDK component of BUILD_DIR into WORK_DIR/prefix,
#  2. configure, build and install examples/minimal_plugin out of tree with find_package(deformbench),
#  3. load the built deform_tethered.so with this build's loader (InstalledPlugin.LoadsByPath),
#  4. load it again through the installed core, found only by the relocated-install search path
#     (InstalledPlugin.FoundInRelocatedInstall).
foreach(v BUILD_DIR EXAMPLE_DIR WORK_DIR TEST_EXE GENERATOR)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "install_test.cmake: ${v} not set")
  endif()
endforeach()

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}\n${err}")
  endif()
  set(RUN_OUTPUT "${out}" PARENT_SCOPE)
endfunction()

set(prefix ${WORK_DIR}/prefix)
set(build ${WORK_DIR}/build)
file(REMOVE_RECURSE ${WORK_DIR})

run("installing the SDK" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix} --component sdk)
file(GLOB_RECURSE config ${prefix}/deformbenchConfig.cmake)
file(GLOB_RECURSE core ${prefix}/libdeform_core.so)
if(NOT config OR NOT core)
  message(FATAL_ERROR "the install lacks deformbenchConfig.cmake or libdeform_core.so")
endif()
get_filename_component(libdir ${core} DIRECTORY)
get_filename_component(config_dir ${config} DIRECTORY)

set(compiler_arg)
if(CXX_COMPILER)
  set(compiler_arg -DCMAKE_CXX_COMPILER=${CXX_COMPILER})
endif()
run("configuring examples/minimal_plugin" ${CMAKE_COMMAND} -S ${EXAMPLE_DIR} -B ${build}
    -G ${GENERATOR} ${compiler_arg} -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${prefix}
    -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
# The package must come from the scratch prefix, not from some other installation.
file(STRINGS ${build}/CMakeCache.txt found REGEX "^deformbench_DIR:")
string(REGEX REPLACE "^deformbench_DIR:[A-Z]+=" "" found "${found}")
file(REAL_PATH "${found}" found)
file(REAL_PATH "${config_dir}" config_dir)
if(NOT found STREQUAL config_dir)
  message(FATAL_ERROR "find_package(deformbench) found '${found}', expected '${config_dir}'")
endif()
run("building examples/minimal_plugin" ${CMAKE_COMMAND} --build ${build})
run("installing examples/minimal_plugin" ${CMAKE_COMMAND} --install ${build})

set(plugin ${build}/deform_tethered.so)
set(installed_plugin ${libdir}/deformbench/plugins/deform_tethered.so)
foreach(f ${plugin} ${installed_plugin})
  if(NOT EXISTS ${f})
    message(FATAL_ERROR "expected ${f} to exist")
  endif()
endforeach()

# gtest exits 0 when a filter matches nothing, so check that the test really ran and passed.
function(run_gtest name)
  run("${name}" ${CMAKE_COMMAND} -E env ${ARGN} ${TEST_EXE} --gtest_filter=${name})
  if(NOT RUN_OUTPUT MATCHES "\\[       OK \\] ${name}" OR RUN_OUTPUT MATCHES "SKIPPED")
    message(FATAL_ERROR "${name} did not run and pass:\n${RUN_OUTPUT}")
  endif()
  message(STATUS "${name}: passed")
endfunction()

run_gtest(InstalledPlugin.LoadsByPath --unset=DEFORM_PLUGIN_PATH DEFORM_INSTALLED_PLUGIN=${plugin})
# LD_LIBRARY_PATH outranks the test program's RUNPATH, so it runs on the installed libdeform_core,
# whose own location must lead the loader to PREFIX/lib/deformbench/plugins.
run_gtest(InstalledPlugin.FoundInRelocatedInstall --unset=DEFORM_PLUGIN_PATH
          LD_LIBRARY_PATH=${libdir} DEFORM_INSTALLED_PREFIX=${prefix}
          DEFORM_INSTALLED_PLUGIN=${installed_plugin})
