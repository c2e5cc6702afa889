# Issue 19: the sanitizer and fuzzing builds (both off by default; scripts/test_sanitize.sh
# and scripts/fuzz.sh configure them in build-asan/ with clang).
#   CREASE_SANITIZE=ON  every target is built with AddressSanitizer and UndefinedBehaviorSanitizer;
#                       UBSan does not recover, so any report ends the process and fails its test.
#   CREASE_FUZZ=ON      also builds the libFuzzer targets fuzz/*_fuzzer.cc (clang only; implies
#                       CREASE_SANITIZE). Library code gets -fsanitize=fuzzer-no-link (coverage
#                       feedback without libFuzzer's main), so the tests of the same build still link.
option(CREASE_SANITIZE "Build with AddressSanitizer + UndefinedBehaviorSanitizer" OFF)
option(CREASE_FUZZ "Build the libFuzzer targets in fuzz/ (clang only; implies CREASE_SANITIZE)" OFF)

if(CREASE_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR
      "crease: CREASE_FUZZ=ON needs clang (libFuzzer), but the C++ compiler is ${CMAKE_CXX_COMPILER_ID}. "
      "Configure a separate build with -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang "
      "(scripts/fuzz.sh does), or leave CREASE_FUZZ off.")
  endif()
  set(CREASE_SANITIZE ON CACHE BOOL "Build with AddressSanitizer + UndefinedBehaviorSanitizer" FORCE)
endif()

if(CREASE_SANITIZE)
  set(CREASE_SANITIZER_FLAGS -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer)
  add_compile_options(${CREASE_SANITIZER_FLAGS})
  add_link_options(${CREASE_SANITIZER_FLAGS})
  message(STATUS "crease: ASan + UBSan build (non-recoverable)")
endif()
if(CREASE_FUZZ)
  add_compile_options(-fsanitize=fuzzer-no-link)
  message(STATUS "crease: libFuzzer targets in fuzz/")
endif()
