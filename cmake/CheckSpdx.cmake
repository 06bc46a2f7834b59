# SPDX-License-Identifier: MIT
# Fails when a source or build file of the project (under ROOT, not in build/ or
# node_modules/) has no SPDX licence identifier in its first three lines.
file(GLOB_RECURSE files RELATIVE ${ROOT}
  ${ROOT}/*.h ${ROOT}/*.cpp ${ROOT}/*.ts ${ROOT}/*.mjs ${ROOT}/*.sh ${ROOT}/*.cmake
  ${ROOT}/*.in ${ROOT}/CMakeLists.txt)
set(missing "")
foreach(f ${files})
  if(f MATCHES "(^|/)(build|node_modules|out|\\.git)/" OR f MATCHES "^\\.ci/")
    continue()
  endif()
  file(STRINGS ${ROOT}/${f} head LIMIT_COUNT 3)
  string(FIND "${head}" "SPDX-License-Identifier: MIT" at)
  if(at EQUAL -1)
    string(APPEND missing "\n  ${f}")
  endif()
endforeach()
if(missing)
  message(FATAL_ERROR "files without an SPDX-License-Identifier line:${missing}")
endif()
list(LENGTH files n)
message(STATUS "${n} files carry the MIT SPDX identifier")
