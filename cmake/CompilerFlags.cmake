# Warnings and optimisation for crease's own targets (third-party headers come
# in through imported targets, i.e. -isystem, so they do not warn).
add_compile_options(-Wall -Wextra -Wno-unused-parameter)
if(CMAKE_BUILD_TYPE STREQUAL "Release")
  add_compile_options(-O3)
endif()
# Eigen's static alignment assumptions must agree across all our objects.
add_compile_definitions(EIGEN_MPL2_ONLY)
