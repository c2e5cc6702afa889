# The one place crease looks for third-party libraries. Every failure names the
# Debian 12 package that provides the library (all are listed in scripts/deps.txt
# and installed by scripts/setup.sh).

macro(crease_require name package)
  find_package(${name} ${ARGN} QUIET)
  if(NOT ${name}_FOUND)
    message(FATAL_ERROR
      "crease: could not find ${name}. Install the Debian package: "
      "sudo apt-get install ${package}   (or run scripts/setup.sh, which installs all of scripts/deps.txt)")
  endif()
endmacro()

crease_require(Eigen3 libeigen3-dev 3.4 NO_MODULE)
crease_require(TBB libtbb-dev)
crease_require(ZLIB zlib1g-dev)
crease_require(OpenCV "libopencv-dev libopencv-contrib-dev" 4 COMPONENTS core imgproc imgcodecs video calib3d objdetect videoio)
crease_require(embree libembree-dev 3)
crease_require(nlohmann_json nlohmann-json3-dev 3)
crease_require(yaml-cpp libyaml-cpp-dev)
crease_require(CLI11 libcli11-dev)
crease_require(fmt libfmt-dev)
crease_require(spdlog libspdlog-dev)
# OpenImageIO's CMake config fails unless openimageio-tools is installed (PLATFORM.md).
crease_require(OpenImageIO "libopenimageio-dev openimageio-tools" 2.4)
crease_require(VTK libvtk9-dev 9 COMPONENTS CommonCore CommonDataModel IOXML)
crease_require(Ceres "libceres-dev libgoogle-glog-dev libsuitesparse-dev" 2)
crease_require(dlib "libdlib-dev libdlib-data")
crease_require(TinyGLTF libtinygltf-dev)

if(CREASE_BUILD_TESTS)
  crease_require(GTest libgtest-dev)
endif()
if(CREASE_BUILD_BENCH)
  crease_require(benchmark libbenchmark-dev)
endif()
