# A rerun into a results folder (issue 35, "a failed rerun leaves stale results"). Variables:
#   PROGRAM the deformbench executable, OUT the folder, FIRST a scene with runs "a" and "b",
#   SECOND a scene with run "a" only whose surface is larger than 16 KiB.
# 1. FIRST into OUT. 2. SECOND with a 16 KiB file size limit (writes fail with EFBIG, as on a
# full disk): exit 2, and OUT holds FIRST's results.json and surfaces unchanged, no staging
# folder. 3. SECOND without the limit: its results, and b/ (FIRST's) is gone.
file(REMOVE_RECURSE "${OUT}")
function(run_ok scene)
  execute_process(COMMAND "${PROGRAM}" run "${scene}" --out "${OUT}" --no-cache
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "run ${scene}: exit ${rc}\n${out}\n${err}")
  endif()
endfunction()
run_ok("${FIRST}")
file(SHA256 "${OUT}/results.json" results1)
file(SHA256 "${OUT}/a/final.obj" surface1)
execute_process(COMMAND bash -c "trap '' XFSZ; ulimit -f 16; exec \"$0\" \"$@\""
                        "${PROGRAM}" run "${SECOND}" --out "${OUT}" --no-cache
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message(STATUS "limited rerun: exit ${rc}\n${out}\n${err}")
if(NOT rc EQUAL 2)
  message(FATAL_ERROR "the rerun that cannot write exited ${rc}, expected 2")
endif()
file(SHA256 "${OUT}/results.json" results2)
file(SHA256 "${OUT}/a/final.obj" surface2)
if(NOT results1 STREQUAL results2 OR NOT surface1 STREQUAL surface2)
  message(FATAL_ERROR "the failed rerun changed the previous results")
endif()
file(GLOB staging "${OUT}/.staging.*")
if(staging)
  message(FATAL_ERROR "staging left behind: ${staging}")
endif()
run_ok("${SECOND}")
file(READ "${OUT}/results.json" doc)
string(FIND "${doc}" "one-pbd-liver" pos)
if(pos EQUAL -1)
  message(FATAL_ERROR "results.json is not the rerun's")
endif()
if(EXISTS "${OUT}/b")
  message(FATAL_ERROR "b/ of the first run is still there")
endif()
