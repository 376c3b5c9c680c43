# tessera_embed_files(TARGET NAME FILES f1 f2 ... BASE dir)
# Generates a C++ source that holds the given files as byte arrays, with a lookup table keyed by the path relative
# to BASE, and adds it to TARGET. Used to compile the API contract (proto/) and the web client into the binaries, so
# the daemon runs with no files beside it.
function(tessera_embed_files target)
  cmake_parse_arguments(ARG "" "NAME;BASE" "FILES" ${ARGN})
  set(out "${CMAKE_CURRENT_BINARY_DIR}/${ARG_NAME}_embedded.cpp")
  add_custom_command(
    OUTPUT "${out}"
    COMMAND ${CMAKE_COMMAND} -DOUT=${out} -DNAME=${ARG_NAME} -DBASE=${ARG_BASE} "-DFILES=${ARG_FILES}"
            -P "${PROJECT_SOURCE_DIR}/cmake/EmbedFilesScript.cmake"
    DEPENDS ${ARG_FILES} "${PROJECT_SOURCE_DIR}/cmake/EmbedFilesScript.cmake"
    COMMENT "Embedding ${ARG_NAME}"
    VERBATIM)
  target_sources(${target} PRIVATE "${out}")
endfunction()
