# FindSleef: SLEEF, the vectorized libm, as Debian's libsleef-dev installs it
# (sleef.h and libsleef.so, no CMake package of its own; the header lies in the multiarch include
# directory, which find_path searches through CMAKE_LIBRARY_ARCHITECTURE).
#
# Defines the imported target Sleef::sleef, Sleef_FOUND, Sleef_VERSION (from sleef.h),
# Sleef_INCLUDE_DIR and Sleef_LIBRARY. Used by the project's build (core/CMakeLists.txt) and
# installed next to lpoe_calibConfig.cmake, which finds SLEEF the same way for downstream projects.
find_path(Sleef_INCLUDE_DIR NAMES sleef.h)
find_library(Sleef_LIBRARY NAMES sleef)
if(Sleef_INCLUDE_DIR AND EXISTS "${Sleef_INCLUDE_DIR}/sleef.h")
  file(STRINGS "${Sleef_INCLUDE_DIR}/sleef.h" _sleef_version_lines
       REGEX "^#define SLEEF_VERSION_(MAJOR|MINOR|PATCHLEVEL) [0-9]+")
  foreach(_part MAJOR MINOR PATCHLEVEL)
    string(REGEX REPLACE ".*#define SLEEF_VERSION_${_part} ([0-9]+).*" "\\1" _sleef_${_part}
           "${_sleef_version_lines}")
  endforeach()
  set(Sleef_VERSION "${_sleef_MAJOR}.${_sleef_MINOR}.${_sleef_PATCHLEVEL}")
  unset(_sleef_version_lines)
endif()
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Sleef REQUIRED_VARS Sleef_LIBRARY Sleef_INCLUDE_DIR
                                  VERSION_VAR Sleef_VERSION)
if(Sleef_FOUND AND NOT TARGET Sleef::sleef)
  add_library(Sleef::sleef UNKNOWN IMPORTED)
  set_target_properties(Sleef::sleef PROPERTIES
    IMPORTED_LOCATION "${Sleef_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${Sleef_INCLUDE_DIR}")
endif()
mark_as_advanced(Sleef_INCLUDE_DIR Sleef_LIBRARY)
