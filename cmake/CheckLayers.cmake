# SPDX-License-Identifier: MIT
# Fails when a file of the core layer (FILES, |-separated) includes a header of a higher layer
# or of file, CLI, HTTP, MQTT, database or logging code. Writes STAMP when all pass.
set(forbidden
  "<fstream>" "<iostream>" "<cstdio>" "<stdio.h>" "<filesystem>"
  "<nlohmann/" "<httplib.h>" "<CLI/" "<sqlite3.h>" "<mqtt/" "<spdlog/"
  "\"trailmark/io/" "\"trailmark/pipelines/" "\"trailmark/report/" "\"server/")
string(REPLACE "|" ";" files "${FILES}")
set(problems "")
foreach(file ${files})
  file(STRINGS ${file} lines REGEX "^[ \t]*#[ \t]*include")
  foreach(line ${lines})
    foreach(pattern ${forbidden})
      string(FIND "${line}" "${pattern}" at)
      if(NOT at EQUAL -1)
        string(APPEND problems "\n  ${file}: ${line}")
      endif()
    endforeach()
  endforeach()
endforeach()
if(problems)
  message(FATAL_ERROR "the core layer (no I/O) includes a forbidden header:${problems}")
endif()
file(WRITE ${STAMP} "ok\n")
