# cmake -P script run by CTest (test plugin_sdk_install_export), the steps of README "Install" and
# examples/minimal_plugin/README.md as an author runs them:
#  1. install BUILD_DIR into WORK_DIR/prefix (cmake --install BUILD --prefix P): no engine target
#     exported, no engine or internal header installed, the former header names forwarding,
#  2. configure, build and install examples/minimal_plugin out of tree with find_package(deformbench),
#  3. load the built deform_tethered.so with this build's loader (InstalledPlugin.LoadsByPath),
#  4. load it again through the installed core, found only by the relocated-install search path
#     (InstalledPlugin.FoundInRelocatedInstall),
#  5. compare it with pbd in the example's scene (run, then report),
#  6. configure the example against the build tree (-Ddeformbench_DIR=BUILD_DIR).
# The conformance suite on the built example is the test conformance_example, which needs this
# one (CTest fixture example_plugin: WORK_DIR/prefix/bin/deformbench, WORK_DIR/build).
cmake_minimum_required(VERSION 3.22)
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
  set(RUN_ERROR "${err}" PARENT_SCOPE)
endfunction()

set(prefix ${WORK_DIR}/prefix)
set(build ${WORK_DIR}/build)
file(REMOVE_RECURSE ${WORK_DIR})

run("installing deformbench" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
file(GLOB_RECURSE config ${prefix}/deformbenchConfig.cmake)
file(GLOB_RECURSE core ${prefix}/libdeform_sdk.so)
if(NOT config OR NOT core)
  message(FATAL_ERROR "the install lacks deformbenchConfig.cmake or libdeform_sdk.so")
endif()
get_filename_component(libdir ${core} DIRECTORY)
get_filename_component(config_dir ${config} DIRECTORY)

# The package gives plugins the SDK and never the engine: no engine target is exported, no
# engine or internal header installed; the headers' former names still forward.
file(GLOB targets_files ${config_dir}/deformbenchTargets*.cmake)
foreach(f ${targets_files})
  file(READ ${f} text)
  if(text MATCHES "deform_engine|deform_core_internal")
    message(FATAL_ERROR "${f} exports an engine or internal target")
  endif()
endforeach()
file(GLOB_RECURSE engine_headers ${prefix}/include/deform/engine/*.h ${prefix}/include/deform/internal/*.h)
if(engine_headers)
  message(FATAL_ERROR "engine or internal headers installed: ${engine_headers}")
endif()
foreach(h sdk/model.h geometry/mesh_io.h kernels/sparse.h model.h)
  if(NOT EXISTS ${prefix}/include/deform/${h})
    message(FATAL_ERROR "the install lacks include/deform/${h}")
  endif()
endforeach()

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
# LD_LIBRARY_PATH outranks the test program's RUNPATH, so it runs on the installed core libraries,
# whose own location must lead the loader to PREFIX/lib/deformbench/plugins.
run_gtest(InstalledPlugin.FoundInRelocatedInstall --unset=DEFORM_PLUGIN_PATH
          LD_LIBRARY_PATH=${libdir} DEFORM_INSTALLED_PREFIX=${prefix}
          DEFORM_INSTALLED_PLUGIN=${installed_plugin})

set(deformbench ${prefix}/bin/deformbench)

# 5. The example next to pbd in its scene (no reference and 150 steps: seconds), then the report.
#    The installed copy must load the pbd installed beside it.
file(GLOB pbd ${BUILD_DIR}/plugins/deform_pbd.so)
if(pbd)
  run("deformbench run compare_with_pbd.json" ${CMAKE_COMMAND} -E env --unset=DEFORM_PLUGIN_PATH
      ${deformbench} --plugin-dir ${build} run ${EXAMPLE_DIR}/compare_with_pbd.json
      --out ${WORK_DIR}/compare --no-reference --no-cache --steps 150 --strict --explain)
  # The installed copy runs its own pbd, not the build tree's (which it also knows of).
  if(NOT "${RUN_OUTPUT}${RUN_ERROR}" MATCHES "loaded plugin ${libdir}/deformbench/plugins/deform_pbd.so")
    message(FATAL_ERROR "the installed deformbench did not load its own pbd:\n${RUN_OUTPUT}${RUN_ERROR}")
  endif()
  file(READ ${WORK_DIR}/compare/results.json results)
  foreach(label tethered pbd)
    string(JSON n LENGTH "${results}" runs)
    set(ok FALSE)
    math(EXPR last "${n} - 1")
    foreach(i RANGE ${last})
      string(JSON l GET "${results}" runs ${i} label)
      string(JSON st GET "${results}" runs ${i} status)
      if("${l}" STREQUAL "${label}" AND "${st}" STREQUAL "ok")
        set(ok TRUE)
      endif()
    endforeach()
    if(NOT ok)
      message(FATAL_ERROR "results.json has no ok run '${label}':\n${results}")
    endif()
  endforeach()
  run("deformbench report" ${deformbench} report ${WORK_DIR}/compare)
  if(NOT EXISTS ${WORK_DIR}/compare/report.html)
    message(FATAL_ERROR "deformbench report wrote no report.html")
  endif()
  message(STATUS "tethered compared with pbd: ${WORK_DIR}/compare/report.html")
else()
  message(STATUS "pbd not built: comparison step skipped")
endif()

# 6. find_package(deformbench) from the build tree.
run("configuring examples/minimal_plugin against the build tree" ${CMAKE_COMMAND} -S ${EXAMPLE_DIR}
    -B ${WORK_DIR}/build-tree-example -G ${GENERATOR} ${compiler_arg} -DCMAKE_BUILD_TYPE=Release
    -Ddeformbench_DIR=${BUILD_DIR} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
run("building examples/minimal_plugin against the build tree" ${CMAKE_COMMAND}
    --build ${WORK_DIR}/build-tree-example)
message(STATUS "find_package(deformbench) from the build tree: built")
