# FMU building blocks, parametrised by FMI version, platform folder and model description,
# so that another FMI edition of the same models is another call, not a copy.
#
#   piezo_fmi_platform_folder(<fmi version> <CMake system name> <out var>)
#   piezo_add_fmu_binary(<target> OUTPUT_NAME <id> OUTPUT_DIR <dir> SOURCES <.c...>
#                        INCLUDE_DIRS <dir...> [EXPORTS_MAP <version script>])
#   piezo_fmu_check_source_files(<model description> <.c...>)
#   piezo_fmu_reference_results(<id> MODEL_DESCRIPTION <xml> OUT_DIR <dir> STAMP_VAR <var>)
#   piezo_fmu_package(ID <id> FMI_VERSION <2.0|3.0> MODEL_DESCRIPTION <xml> OUTPUT <.fmu>
#                     BINARIES <platform folder> <file> [<platform folder> <file>...]
#                     [BINARY_DEPENDS <targets...>] SOURCES <.c...> HEADERS <.h...>
#                     [DEFINES <NAME[=value]>...] ICON <png> DOCUMENTATION <html fragment>
#                     [EXTRA_DIR <dir> EXTRA_STAMP <file>])
#
# The packaging itself (stamping the model description, buildDescription.xml,
# documentation/index.html, the reproducible zip) is packaging/assemble_fmu.py.

include_guard(GLOBAL)

set(PIEZO_PACKAGING_DIR "${CMAKE_CURRENT_LIST_DIR}/../packaging")
get_filename_component(PIEZO_PACKAGING_DIR "${PIEZO_PACKAGING_DIR}" ABSOLUTE)

# FMI 2.0 names the platform folders linux64/win64, FMI 3.0 x86_64-linux/x86_64-windows.
function(piezo_fmi_platform_folder fmi_version system out_var)
  if(fmi_version VERSION_LESS 3)
    set(names_Linux linux64)
    set(names_Windows win64)
    set(names_Darwin darwin64)
  else()
    set(names_Linux x86_64-linux)
    set(names_Windows x86_64-windows)
    set(names_Darwin x86_64-darwin)
  endif()
  if(NOT DEFINED names_${system})
    message(FATAL_ERROR "no FMI ${fmi_version} platform folder for system '${system}'")
  endif()
  set(${out_var} "${names_${system}}" PARENT_SCOPE)
endfunction()

# Whether the FMU binaries get link-time optimisation (checked once per configure).
function(piezo_fmu_ipo out_var)
  if(PIEZO_SANITIZE OR PIEZO_FUZZ)
    set(${out_var} FALSE PARENT_SCOPE)
    return()
  endif()
  get_property(known GLOBAL PROPERTY PIEZO_FMU_IPO SET)
  if(NOT known)
    include(CheckIPOSupported)
    check_ipo_supported(RESULT supported OUTPUT why LANGUAGES C)
    if(NOT supported)
      message(STATUS "FMU binaries without link-time optimisation: ${why}")
    endif()
    set_property(GLOBAL PROPERTY PIEZO_FMU_IPO ${supported})
  endif()
  get_property(supported GLOBAL PROPERTY PIEZO_FMU_IPO)
  set(${out_var} ${supported} PARENT_SCOPE)
endfunction()

# A loadable FMU binary <OUTPUT_NAME>.so/.dll in OUTPUT_DIR, exporting the FMI API only.
function(piezo_add_fmu_binary target)
  cmake_parse_arguments(ARG "" "OUTPUT_NAME;OUTPUT_DIR;EXPORTS_MAP" "SOURCES;INCLUDE_DIRS" ${ARGN})
  add_library(${target} MODULE ${ARG_SOURCES})
  target_include_directories(${target} PRIVATE ${ARG_INCLUDE_DIRS})
  # The FMI glue, the model and the core are separate files: link-time optimisation
  # lets the compiler inline across them (the doStep, get and set paths into the core)
  # as within one file. It does not touch the arithmetic (no -ffast-math, no
  # contraction: a binary built from sources/ without it gives the same results).
  # Off for the sanitizer and fuzz builds, and where the toolchain cannot do it.
  piezo_fmu_ipo(ipo)
  if(ipo)
    set_property(TARGET ${target} PROPERTY INTERPROCEDURAL_OPTIMIZATION TRUE)
  endif()
  set_target_properties(${target} PROPERTIES
    PREFIX "" OUTPUT_NAME "${ARG_OUTPUT_NAME}"
    C_VISIBILITY_PRESET hidden
    LIBRARY_OUTPUT_DIRECTORY "${ARG_OUTPUT_DIR}"
    RUNTIME_OUTPUT_DIRECTORY "${ARG_OUTPUT_DIR}")
  if(WIN32)
    # Only system DLLs at run time (static libgcc), no time stamp in the PE header
    # (same commit, same bytes), no symbol table; MODULE libraries get no import library.
    # mingw's own C99 printf, so %zu and %lld in log messages print what they say.
    target_compile_definitions(${target} PRIVATE __USE_MINGW_ANSI_STDIO=1)
    target_link_options(${target} PRIVATE -static-libgcc "LINKER:--no-insert-timestamp" -s)
  else()
    target_link_libraries(${target} PRIVATE m)
    target_link_options(${target} PRIVATE "LINKER:--no-undefined")
    if(ARG_EXPORTS_MAP)
      target_link_options(${target} PRIVATE "LINKER:--version-script=${ARG_EXPORTS_MAP}")
      set_property(TARGET ${target} APPEND PROPERTY LINK_DEPENDS "${ARG_EXPORTS_MAP}")
    endif()
  endif()
endfunction()

# Fails unless <SourceFiles> of `xml` names exactly the basenames of the given .c files.
function(piezo_fmu_check_source_files xml)
  file(READ "${xml}" text)
  string(REGEX MATCH "<SourceFiles>.*</SourceFiles>" block "${text}")
  string(REGEX MATCHALL "<File[ \t\r\n]+name=\"[^\"]*\"" entries "${block}")
  set(listed "")
  foreach(entry IN LISTS entries)
    string(REGEX REPLACE ".*name=\"([^\"]*)\"" "\\1" name "${entry}")
    list(APPEND listed "${name}")
  endforeach()
  set(compiled "")
  foreach(file IN LISTS ARGN)
    get_filename_component(name "${file}" NAME)
    list(APPEND compiled "${name}")
  endforeach()
  list(SORT listed)
  list(SORT compiled)
  if(NOT listed STREQUAL compiled)
    message(FATAL_ERROR "${xml}: <SourceFiles> lists [${listed}] but the binary is built from [${compiled}]")
  endif()
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${xml}")
endfunction()

# The date every FMU is stamped with: the commit's (SOURCE_DATE_EPOCH overrides), and the
# source it is built from (the commit, and whether the tracked files had uncommitted
# changes: PIEZO_SOURCE_FILE, harness/_source.py), checked at every build.
# Each file is rewritten only when it changes, so a new commit (or a tree that becomes
# clean or dirty) re-stamps the FMUs and an unchanged one leaves them alone.
set(PIEZO_SOURCE_FILE "${CMAKE_BINARY_DIR}/source.json")
function(piezo_commit_date_target out_var)
  set(file "${CMAKE_BINARY_DIR}/piezo_commit_date.txt")
  if(NOT TARGET piezo_commit_date)
    add_custom_target(piezo_commit_date ALL
      COMMAND "${PIEZO_PYTHON}" "${PIEZO_PACKAGING_DIR}/assemble_fmu.py" commit-date
              --repo "${CMAKE_SOURCE_DIR}" --out "${file}" --source-out "${PIEZO_SOURCE_FILE}"
      BYPRODUCTS "${file}" "${PIEZO_SOURCE_FILE}"
      COMMENT "Commit date and source for the FMUs"
      VERBATIM)
  endif()
  set(${out_var} "${file}" PARENT_SCOPE)
endfunction()

# Reference results of the FMU (FMI-LS-REF): stimuli, parameters, reference outputs, the
# experiments file and the manifest, computed on the C core (not through the FMU) by
# harness/buildtime/references.py into OUT_DIR; STAMP_VAR receives the file to depend on.
function(piezo_fmu_reference_results id)
  cmake_parse_arguments(ARG "" "MODEL_DESCRIPTION;OUT_DIR;STAMP_VAR" "" ${ARGN})
  set(stamp "${ARG_OUT_DIR}.stamp")
  file(GLOB harness_sources CONFIGURE_DEPENDS "${CMAKE_SOURCE_DIR}/harness/*.py"
       "${CMAKE_SOURCE_DIR}/harness/scenarios/*.toml")
  add_custom_command(
    OUTPUT "${stamp}"
    COMMAND "${CMAKE_COMMAND}" -E env
            "PIEZO_CORE_LIB=$<TARGET_FILE:piezo_core>" "PIEZO_CORE_INCLUDE=${CORE_DIR}"
            "${PIEZO_PYTHON}" -m harness.buildtime.references
            --model "${id}" --model-description "${ARG_MODEL_DESCRIPTION}"
            --out "${ARG_OUT_DIR}" --stamp "${stamp}"
    WORKING_DIRECTORY "${CMAKE_SOURCE_DIR}"
    DEPENDS piezo_core "${ARG_MODEL_DESCRIPTION}" "${CMAKE_SOURCE_DIR}/harness/buildtime/references.py"
            ${harness_sources}
    COMMENT "Reference results of ${id}"
    VERBATIM)
  set(${ARG_STAMP_VAR} "${stamp}" PARENT_SCOPE)
endfunction()

function(piezo_fmu_package)
  cmake_parse_arguments(ARG ""
    "ID;FMI_VERSION;MODEL_DESCRIPTION;OUTPUT;ICON;DOCUMENTATION;EXTRA_DIR;EXTRA_STAMP"
    "BINARIES;BINARY_DEPENDS;SOURCES;HEADERS;DEFINES" ${ARGN})
  piezo_commit_date_target(date_file)
  set(binary_args "")
  set(binary_files "")
  list(LENGTH ARG_BINARIES n)
  math(EXPR last "${n} - 1")
  foreach(i RANGE 0 ${last} 2)
    math(EXPR j "${i} + 1")
    list(GET ARG_BINARIES ${i} folder)
    list(GET ARG_BINARIES ${j} file)
    list(APPEND binary_args --binary "${folder}=${file}")
    list(APPEND binary_files "${file}")
  endforeach()
  set(define_args "")
  foreach(def IN LISTS ARG_DEFINES)
    list(APPEND define_args --define "${def}")
  endforeach()
  set(extra_args "")
  if(ARG_EXTRA_DIR)
    set(extra_args --extra-dir "${ARG_EXTRA_DIR}")
  endif()
  set(stage "${CMAKE_BINARY_DIR}/fmu_stage/fmi${ARG_FMI_VERSION}/${ARG_ID}")
  set(project_version "${PIEZO_PROJECT_VERSION}")
  add_custom_command(
    OUTPUT "${ARG_OUTPUT}"
    COMMAND "${PIEZO_PYTHON}" "${PIEZO_PACKAGING_DIR}/assemble_fmu.py" assemble
            --id "${ARG_ID}" --fmi-version "${ARG_FMI_VERSION}"
            --model-description "${ARG_MODEL_DESCRIPTION}"
            --version "${project_version}" --date-file "${date_file}"
            --source-file "${PIEZO_SOURCE_FILE}"
            ${binary_args}
            --sources ${ARG_SOURCES} --headers ${ARG_HEADERS} ${define_args}
            --icon "${ARG_ICON}" --documentation "${ARG_DOCUMENTATION}"
            --license "${CMAKE_SOURCE_DIR}/LICENSE" ${extra_args}
            --stage "${stage}" --out "${ARG_OUTPUT}"
    WORKING_DIRECTORY "${CMAKE_SOURCE_DIR}"
    DEPENDS ${ARG_BINARY_DEPENDS} ${binary_files} "${ARG_MODEL_DESCRIPTION}"
            ${ARG_SOURCES} ${ARG_HEADERS} "${ARG_ICON}" "${ARG_DOCUMENTATION}"
            "${CMAKE_SOURCE_DIR}/LICENSE" ${ARG_EXTRA_STAMP} "${date_file}" "${PIEZO_SOURCE_FILE}"
            piezo_commit_date "${CMAKE_SOURCE_DIR}/harness/_source.py"
            "${PIEZO_PACKAGING_DIR}/assemble_fmu.py" "${CMAKE_SOURCE_DIR}/harness/buildtime/documentation.py"
            "${CMAKE_SOURCE_DIR}/harness/buildtime/archive.py"
            "${CMAKE_SOURCE_DIR}/harness/buildtime/ssp_file.py"
    COMMENT "Packaging ${ARG_ID}.fmu (FMI ${ARG_FMI_VERSION})"
    VERBATIM)
endfunction()
