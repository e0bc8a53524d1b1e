# Embeds kernels/*.cl as C++ string literals at build time, inlining the `#include "x.h"` and
# `#include "x.cl"` lines (at the start of a line) that name a file in the same folder: the layout
# header shared with the host, and the stage files of a kernel split by stage (hemicube.cl).
# Includes are inlined recursively, each file once per embedded kernel (a second include of it
# becomes a comment). A .cl file that another kernel file includes is a part, not a kernel of its
# own, and is not embedded alone. The .cl files stay plain OpenCL C, so editors and clang-format
# see real code.
#
# The embedded text carries #line directives, so that a device compiler's diagnostics name the
# real file and line (kernels/FILE:LINE): `#line 1 "kernels/FILE"` first, at the start of every
# inlined file, and `#line N "kernels/PARENT"` after each inlined include, N the line after the
# include's. An include inside an #if/#ifdef/#ifndef group is refused: where the group is
# skipped, so is the #line back to the parent, and every line after would be misnumbered (put the
# condition inside the included file instead).
#
# Script mode: cmake -DOUTPUT=file.cpp -DKERNEL_DIR=dir -DKERNELS="a.cl|b.cl" -P EmbedKernels.cmake

cmake_minimum_required(VERSION 3.21)  # (script mode: IN_LIST and the rest of today's policies)

set(HEMIRAD_INCLUDE_REGEX "(^|\n)[ \t]*#[ \t]*include[ \t]*\"([A-Za-z0-9_]+\\.(h|cl))\"[^\n]*")

# The number of newlines in `text`.
function(hemirad_count_newlines text out)
  string(REGEX REPLACE "[^\n]" "" newlines "${text}")
  string(LENGTH "${newlines}" count)
  set(${out} ${count} PARENT_SCOPE)
endfunction()

# The names of the files in `dir` that `text` includes (quoted, at the start of a line).
function(hemirad_included_names text dir out)
  set(names "")
  string(REGEX MATCHALL "${HEMIRAD_INCLUDE_REGEX}" includes "${text}")
  foreach(inc IN LISTS includes)
    string(REGEX REPLACE "${HEMIRAD_INCLUDE_REGEX}" "\\2" name "${inc}")
    if(EXISTS "${dir}/${name}")
      list(APPEND names "${name}")
    endif()
  endforeach()
  set(${out} "${names}" PARENT_SCOPE)
endfunction()

# kernels/`name` with its includes inlined and #line directives (see above). The files already
# inlined for this kernel are in the global property HEMIRAD_INLINED.
function(hemirad_read_inlined name dir out)
  set_property(GLOBAL APPEND PROPERTY HEMIRAD_INLINED "${name}")
  file(READ "${dir}/${name}" rest)
  set(result "#line 1 \"kernels/${name}\"\n")
  set(line 1)    # the line of `name` that `rest` starts on
  set(depth 0)   # open #if groups before `rest`
  while(TRUE)
    string(REGEX MATCH "${HEMIRAD_INCLUDE_REGEX}" directive "${rest}")
    if(directive STREQUAL "")
      break()
    endif()
    string(FIND "${rest}" "${directive}" at)
    string(SUBSTRING "${rest}" 0 ${at} before)
    string(LENGTH "${directive}" length)
    math(EXPR after "${at} + ${length}")
    string(SUBSTRING "${rest}" ${after} -1 rest)
    if(directive MATCHES "^\n")  # the newline ends the line before the include
      string(APPEND before "\n")
      string(SUBSTRING "${directive}" 1 -1 directive)
    endif()
    string(REGEX REPLACE "${HEMIRAD_INCLUDE_REGEX}" "\\2" child "${directive}")
    hemirad_count_newlines("${before}" newlines)
    math(EXPR line "${line} + ${newlines}")  # the include's line
    string(REGEX MATCHALL "(^|\n)[ \t]*#[ \t]*if" opened "${before}")
    string(REGEX MATCHALL "(^|\n)[ \t]*#[ \t]*endif" closed "${before}")
    list(LENGTH opened opened)
    list(LENGTH closed closed)
    math(EXPR depth "${depth} + ${opened} - ${closed}")
    string(APPEND result "${before}")
    get_property(inlined GLOBAL PROPERTY HEMIRAD_INLINED)
    if(NOT EXISTS "${dir}/${child}")
      string(APPEND result "${directive}")  # not ours (the compiler's to find): left as it is
    elseif("${child}" IN_LIST inlined)
      string(APPEND result "// ${directive} (inlined above)")
    elseif(depth GREATER 0)
      message(FATAL_ERROR "kernels/${name}:${line}: #include \"${child}\" inside an #if group: the #line "
                          "directives around it would be skipped with the group and misnumber every line "
                          "after it. Put the condition inside ${child} instead.")
    else()
      hemirad_read_inlined("${child}" "${dir}" child_text)
      if(NOT child_text MATCHES "\n$")
        string(APPEND child_text "\n")
      endif()
      math(EXPR next "${line} + 1")
      string(APPEND result "${child_text}#line ${next} \"kernels/${name}\"")
    endif()
    # `rest` starts with the newline that ended the include's line, still on that line.
  endwhile()
  string(APPEND result "${rest}")
  set(${out} "${result}" PARENT_SCOPE)
endfunction()

if(CMAKE_SCRIPT_MODE_FILE)
  string(REPLACE "|" ";" KERNELS "${KERNELS}")
  # Parts: the .cl files some kernel file includes.
  set(parts "")
  foreach(kernel IN LISTS KERNELS)
    file(READ "${KERNEL_DIR}/${kernel}" text)
    hemirad_included_names("${text}" "${KERNEL_DIR}" names)
    list(APPEND parts ${names})
  endforeach()
  set(body "// Generated by cmake/EmbedKernels.cmake from kernels/*.cl. Do not edit.\n")
  string(APPEND body "#include <map>\n#include <stdexcept>\n#include <string>\n#include <string_view>\n\n")
  string(APPEND body "#include \"cl/runtime.h\"\n\nnamespace hemirad::ocl {\nnamespace {\n")
  string(APPEND body "const std::map<std::string_view, std::string_view>& sources() {\n")
  string(APPEND body "    static const std::map<std::string_view, std::string_view> table = {\n")
  foreach(kernel IN LISTS KERNELS)
    if("${kernel}" IN_LIST parts)
      continue()
    endif()
    set_property(GLOBAL PROPERTY HEMIRAD_INLINED "")
    hemirad_read_inlined("${kernel}" "${KERNEL_DIR}" text)
    # Raw string literals in chunks: compilers limit the length of one literal.
    string(LENGTH "${text}" len)
    set(pieces "")
    set(pos 0)
    while(pos LESS len)
      string(SUBSTRING "${text}" ${pos} 8000 piece)
      string(APPEND pieces "R\"hemirad_cl(${piece})hemirad_cl\"\n")
      math(EXPR pos "${pos} + 8000")
    endwhile()
    string(APPEND body "        {\"${kernel}\", ${pieces}},\n")
  endforeach()
  string(APPEND body "    };\n    return table;\n}\n}  // namespace\n\n")
  string(APPEND body "std::string_view kernel_source(std::string_view name) {\n")
  string(APPEND body "    const auto it = sources().find(name);\n")
  string(APPEND body "    if (it == sources().end()) throw std::out_of_range(\"no embedded kernel \" + std::string(name));\n")
  string(APPEND body "    return it->second;\n}\n\n}  // namespace hemirad::ocl\n")
  file(WRITE "${OUTPUT}.tmp" "${body}")
  file(COPY_FILE "${OUTPUT}.tmp" "${OUTPUT}" ONLY_IF_DIFFERENT)
  file(REMOVE "${OUTPUT}.tmp")
endif()
