# bench.quick: every study of volcast-bench on tiny sizes, then the files each must write.
# Usage: cmake -DBENCH=volcast-bench -DOUT=folder [-DDATA=scans] -P check_quick.cmake
file(REMOVE_RECURSE "${OUT}")
execute_process(COMMAND "${BENCH}" all --quick --out "${OUT}" --repeats 2 RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "volcast-bench all --quick failed: ${rc}")
endif()
foreach(f table1.json table1.csv table1.md table1.svg
          table2_prefilter.json table2_prefilter.csv table2_prefilter.md table2_prefilter.svg
          figure5.json figure5.csv figure5.md figure5_paper.svg figure5_accelerated.svg
          error_vs_time.json error_vs_time.csv error_vs_time.md error_vs_time_bonsai.svg
          error_vs_time_bonsai_samples.svg
          error_synthetic.json error_synthetic.csv error_synthetic.md error_synthetic_narrow_on_wide.svg)
  if(NOT EXISTS "${OUT}/${f}")
    message(FATAL_ERROR "volcast-bench all --quick wrote no ${f}")
  endif()
endforeach()
file(READ "${OUT}/table2_prefilter.json" prefilter)
string(JSON diff GET "${prefilter}" volumes 0 max_abs_difference_opencl_vs_simple)
# The OpenCL prefilter computes in float like the simple one; the phantom's values are ≤ 255,
# so float rounding over a few dozen operations stays far below 1e-2.
if(diff GREATER 0.01)
  message(FATAL_ERROR "OpenCL and simple prefilters differ by ${diff}")
endif()

# The peers' interface: one JSON line per size with resolution and render_ms.
if(DATA AND EXISTS "${DATA}/headsq.nhdr")
  execute_process(COMMAND "${BENCH}" peers --volume "${DATA}/headsq.nhdr" --size 32x24,40x30 --frames 2
                  RESULT_VARIABLE rc OUTPUT_VARIABLE lines)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "volcast-bench peers failed: ${rc}")
  endif()
  string(REGEX MATCHALL "[^\n]+" lines "${lines}")
  list(LENGTH lines n)
  if(NOT n EQUAL 2)
    message(FATAL_ERROR "volcast-bench peers printed ${n} lines for 2 sizes")
  endif()
  list(GET lines 1 second)
  string(JSON w GET "${second}" resolution 0)
  string(JSON ms GET "${second}" render_ms median)
  if(NOT w EQUAL 40 OR NOT ms GREATER 0)
    message(FATAL_ERROR "volcast-bench peers: bad line ${second}")
  endif()
endif()
if(NOT DATA OR NOT EXISTS "${DATA}/headsq.nhdr")
  message(STATUS "bench.quick: the peers interface check skipped: no headsq.nhdr in VOLCAST_DATA_DIR ('${DATA}'; tests/README.md)")
endif()

# The ladder study on the native path: it runs, writes its files and names a level per session count.
execute_process(COMMAND "${BENCH}" ladder --quick --backend cpu --repeats 2 --sessions 1,32 --out "${OUT}/ladder"
                RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "volcast-bench ladder --quick failed: ${rc}")
endif()
foreach(f ladder.json ladder.csv ladder_choices.csv ladder.md)
  if(NOT EXISTS "${OUT}/ladder/${f}")
    message(FATAL_ERROR "volcast-bench ladder --quick wrote no ${f}")
  endif()
endforeach()
file(READ "${OUT}/ladder/ladder.json" ladder)
string(JSON sessions GET "${ladder}" cells 0 choices 0 sessions_dragging)
if(NOT sessions EQUAL 1)
  message(FATAL_ERROR "volcast-bench ladder --quick: the first choice is for ${sessions} sessions, not 1")
endif()
