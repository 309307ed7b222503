# lpoe_add_shared_library(<name> [PUBLIC deps...] [PRIVATE deps...])
#
# The shared variant of the static library lpoe_<name>, built from the same object code (compiled
# position-independent: CMAKE_POSITION_INDEPENDENT_CODE is on), with the same include directories:
# target lpoe_<name>_shared, alias and exported name lpoe::<name>_shared, file liblpoe_<name>.so
# next to liblpoe_<name>.a. Its lpoe dependencies must be given as their shared variants.
function(lpoe_add_shared_library name)
  cmake_parse_arguments(ARG "" "" "PUBLIC;PRIVATE" ${ARGN})
  set(static lpoe_${name})
  set(shared lpoe_${name}_shared)
  add_library(${shared} SHARED $<TARGET_OBJECTS:${static}>)
  add_library(lpoe::${name}_shared ALIAS ${shared})
  set_target_properties(${shared} PROPERTIES
    EXPORT_NAME ${name}_shared
    OUTPUT_NAME lpoe_${name}
    VERSION ${PROJECT_VERSION}
    SOVERSION ${PROJECT_VERSION_MAJOR}.${PROJECT_VERSION_MINOR}
    INSTALL_RPATH "$ORIGIN")  # the other lpoe shared libraries, wherever the prefix is moved
  get_target_property(includes ${static} INTERFACE_INCLUDE_DIRECTORIES)
  target_include_directories(${shared} PUBLIC ${includes})
  target_link_libraries(${shared} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE})
  install(TARGETS ${shared} EXPORT lpoe_calibTargets
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} NAMELINK_COMPONENT Development)
endfunction()
