# Cross-compile for 64-bit Windows with Debian's MinGW-w64 (apt-get install gcc-mingw-w64-x86-64).
#
#   cmake -S . -B build-win64 -DCMAKE_TOOLCHAIN_FILE=cmake/toolchains/mingw-w64-x86_64.cmake
#
# The main build uses it by itself (ExternalProject, see cmake/PiezoFmu.cmake) to put
# binaries/win64/<id>.dll beside binaries/linux64/<id>.so in every FMU.

set(CMAKE_SYSTEM_NAME Windows)
set(CMAKE_SYSTEM_PROCESSOR x86_64)

set(PIEZO_MINGW_PREFIX x86_64-w64-mingw32)
# Debian ships two thread models; either compiles C the same way
find_program(CMAKE_C_COMPILER NAMES ${PIEZO_MINGW_PREFIX}-gcc ${PIEZO_MINGW_PREFIX}-gcc-win32
             ${PIEZO_MINGW_PREFIX}-gcc-posix REQUIRED)
find_program(CMAKE_RC_COMPILER NAMES ${PIEZO_MINGW_PREFIX}-windres)
find_program(CMAKE_AR NAMES ${PIEZO_MINGW_PREFIX}-ar REQUIRED)
find_program(CMAKE_RANLIB NAMES ${PIEZO_MINGW_PREFIX}-ranlib REQUIRED)

# Look for headers and libraries in the target's sysroot only, programs on the host.
set(CMAKE_FIND_ROOT_PATH /usr/${PIEZO_MINGW_PREFIX})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
