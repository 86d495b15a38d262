# Cross-compile with a GCC cross toolchain named by its target triple, e.g. Debian's
# MinGW-w64 (x86_64-w64-mingw32, i686-w64-mingw32) or gcc-aarch64-linux-gnu:
#
#   cmake -S . -B build-aarch64 -DCMAKE_TOOLCHAIN_FILE=cmake/toolchains/cross-gcc.cmake \
#         -DPIEZO_CROSS_TRIPLE=aarch64-linux-gnu
#
# The main build uses it by itself (an ExternalProject per cross platform of
# harness/platforms.py, see CMakeLists.txt) to put each platform's binaries beside the host's
# in every FMU.

# try_compile projects (compiler checks, check_ipo_supported) read this file again without
# the cache: they find the triple in the environment
if(PIEZO_CROSS_TRIPLE)
  set(ENV{PIEZO_CROSS_TRIPLE} "${PIEZO_CROSS_TRIPLE}")
else()
  set(PIEZO_CROSS_TRIPLE "$ENV{PIEZO_CROSS_TRIPLE}")
endif()
if(NOT PIEZO_CROSS_TRIPLE)
  message(FATAL_ERROR "cross-gcc.cmake needs -DPIEZO_CROSS_TRIPLE=<triple> (e.g. i686-w64-mingw32)")
endif()

if(PIEZO_CROSS_TRIPLE MATCHES "mingw32$")
  set(CMAKE_SYSTEM_NAME Windows)
elseif(PIEZO_CROSS_TRIPLE MATCHES "linux-gnu")
  set(CMAKE_SYSTEM_NAME Linux)
else()
  message(FATAL_ERROR "cross-gcc.cmake: no system for the triple ${PIEZO_CROSS_TRIPLE}")
endif()
string(REGEX REPLACE "-.*" "" CMAKE_SYSTEM_PROCESSOR "${PIEZO_CROSS_TRIPLE}")

# Debian's MinGW-w64 comes in two thread models; either compiles C the same way
find_program(CMAKE_C_COMPILER NAMES ${PIEZO_CROSS_TRIPLE}-gcc ${PIEZO_CROSS_TRIPLE}-gcc-win32
             ${PIEZO_CROSS_TRIPLE}-gcc-posix REQUIRED)
find_program(CMAKE_RC_COMPILER NAMES ${PIEZO_CROSS_TRIPLE}-windres)
find_program(CMAKE_AR NAMES ${PIEZO_CROSS_TRIPLE}-ar REQUIRED)
find_program(CMAKE_RANLIB NAMES ${PIEZO_CROSS_TRIPLE}-ranlib REQUIRED)

# Look for headers and libraries in the target's sysroot only, programs on the host.
set(CMAKE_FIND_ROOT_PATH /usr/${PIEZO_CROSS_TRIPLE})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
