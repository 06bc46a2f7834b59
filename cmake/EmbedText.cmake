# SPDX-License-Identifier: MIT
# Turns a text file into a C++ header holding it as a raw string split into chunks (compilers
# limit the length of one string literal).
file(READ ${IN} content)
string(LENGTH "${content}" len)
set(out "#pragma once\n// Generated from ${IN}; do not edit.\n#include <string_view>\nnamespace trailmark::generated {\ninline constexpr std::string_view kChartJsParts[] = {\n")
set(pos 0)
set(chunk 12000)
while(pos LESS len)
  string(SUBSTRING "${content}" ${pos} ${chunk} piece)
  string(APPEND out "R\"tmkjs(${piece})tmkjs\",\n")
  math(EXPR pos "${pos} + ${chunk}")
endwhile()
string(APPEND out "};\n}\n")
file(WRITE ${OUT} "${out}")
