#include "core/image_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <chrono>
#include <cstring>
#include <fstream>
#include <thread>
#include <csignal>
#include <sys/resource.h>
#include <fmt/format.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/rng.h"
#include "tests/test_util.h"

namespace crease {
namespace {
namespace fs = std::filesystem;

cv::Mat RandomImage(int h, int w, int c, uint64_t seed) {
  cv::Mat m(h, w, CV_32FC(c));
  Rng rng(seed);
  for (int y = 0; y < h; ++y) {
    float* row = m.ptr<float>(y);
    for (int x = 0; x < w * c; ++x) row[x] = static_cast<float>(rng.Uniform(-2.0, 3.0));
  }
  return m;
}

// All image tests in one process: OpenImageIO costs ~0.35 s per process start.
TEST(ImageIo, ExrPngRoundTripsSrgbAndErrors) {
  const fs::path dir = ::crease::testing::TestDir() / "crease_image_io";
  // EXR float: bit-exact, 1 and 3 channels.
  for (int c : {1, 3, 4}) {
    const cv::Mat img = RandomImage(17, 23, c, c);
    const fs::path p = dir / ("img" + std::to_string(c) + ".exr");
    WriteImage(p, img);
    const cv::Mat back = ReadImage(p);
    ASSERT_EQ(back.type(), img.type());
    EXPECT_EQ(cv::norm(img, back, cv::NORM_INF), 0.0) << c << " channels";
  }
  // The same image written twice (a second apart) gives the same bytes: no time stamp.
  {
    auto bytes = [](const fs::path& p) {
      std::ifstream in(p, std::ios::binary);
      return std::string(std::istreambuf_iterator<char>(in), {});
    };
    const cv::Mat img = RandomImage(8, 8, 1, 9);
    WriteImage(dir / "t1.exr", img);
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    WriteImage(dir / "t2.exr", img);
    EXPECT_EQ(bytes(dir / "t1.exr"), bytes(dir / "t2.exr"));
  }
  // PNG 8-bit sRGB: every 8-bit code survives linear→sRGB→linear→sRGB.
  cv::Mat codes(1, 256, CV_32FC1);
  for (int i = 0; i < 256; ++i) codes.at<float>(0, i) = SrgbToLinear(i / 255.0f);
  WriteImage(dir / "codes.png", codes);
  const cv::Mat back = ReadImage(dir / "codes.png");
  for (int i = 0; i < 256; ++i) {
    EXPECT_EQ(cvRound(LinearToSrgb(back.at<float>(0, i)) * 255.0f), i);
  }
  // The sRGB decode of 8- and 16-bit files (one table per code) gives exactly the
  // floats of decoding each pixel read as data; alpha stays linear.
  for (const int bits : {8, 16}) {
    cv::Mat rgba(3, 256, CV_32FC4);
    Rng rng(bits);
    for (int y = 0; y < rgba.rows; ++y) {
      for (int x = 0; x < rgba.cols; ++x) {
        for (int k = 0; k < 4; ++k) rgba.at<cv::Vec4f>(y, x)[k] = static_cast<float>(rng.Uniform(0.0, 1.0));
      }
    }
    rgba.at<cv::Vec4f>(0, 0) = cv::Vec4f(0, 0, 0, 0);
    rgba.at<cv::Vec4f>(0, 1) = cv::Vec4f(1, 1, 1, 1);
    const fs::path p = dir / fmt::format("rgba{}.png", bits);
    WriteImage(p, rgba, {.srgb = false, .bits = bits});
    const cv::Mat decoded = ReadImage(p), data = ReadImage(p, /*srgb=*/false);
    ASSERT_EQ(decoded.type(), CV_32FC4);
    int differ = 0;
    for (int y = 0; y < data.rows; ++y) {
      for (int x = 0; x < data.cols; ++x) {
        const cv::Vec4f d = data.at<cv::Vec4f>(y, x), e = decoded.at<cv::Vec4f>(y, x);
        for (int k = 0; k < 3; ++k) differ += e[k] != SrgbToLinear(d[k]);
        differ += e[3] != d[3];
      }
    }
    EXPECT_EQ(differ, 0) << bits << " bits";
    EXPECT_EQ(decoded.at<cv::Vec4f>(0, 1)[0], 1.0f);
    EXPECT_GT(data.at<cv::Vec4f>(2, 5)[0], decoded.at<cv::Vec4f>(2, 5)[0]);  // decoded: darker mid-tones
  }
  // Linear (data) PNG keeps value·255.
  cv::Mat mask(4, 4, CV_32FC1, cv::Scalar(0.0f));
  mask.at<float>(1, 2) = 1.0f;
  WriteImage(dir / "mask.png", mask, {.srgb = false});
  const cv::Mat mback = ReadImage(dir / "mask.png", /*srgb=*/false);
  EXPECT_EQ(mback.at<float>(1, 2), 1.0f);
  EXPECT_EQ(mback.at<float>(0, 0), 0.0f);

  // Errors name the file.
  try {
    ReadImage(dir / "missing.exr");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.exr: file does not exist"), std::string::npos);
  }
  std::ofstream(dir / "garbage.png") << "this is not a png";
  EXPECT_THROW(ReadImage(dir / "garbage.png"), Error);
  cv::Mat nan_img(2, 2, CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  try {
    WriteImage(dir / "nan.png", nan_img);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nan.png"), std::string::npos);
  }
  EXPECT_FALSE(fs::exists(dir / "nan.png"));
  EXPECT_THROW(WriteImage(dir / "x.unknownext", codes), Error);
  // Issue 19: a PNG whose header claims 100000×100000 (OpenCV was asked for 120 GB)
  // is refused from its header. IHDR: width and height at bytes 16-23, CRC at 29-32.
  {
    std::ifstream in(dir / "codes.png", std::ios::binary);
    std::string png(std::istreambuf_iterator<char>(in), {});
    ASSERT_EQ(png.substr(12, 4), "IHDR");
    auto put_u32 = [&](size_t at, uint32_t v) {
      for (int i = 0; i < 4; ++i) png[at + i] = static_cast<char>(v >> (24 - 8 * i) & 0xff);
    };
    put_u32(16, 100000);
    put_u32(20, 100000);
    uint32_t crc = 0xffffffffu;  // CRC-32 of the chunk type and data, as PNG readers check it
    for (size_t i = 12; i < 29; ++i) {
      crc ^= static_cast<unsigned char>(png[i]);
      for (int k = 0; k < 8; ++k) crc = crc >> 1 ^ (0xedb88320u & (0u - (crc & 1u)));
    }
    put_u32(29, ~crc);
    std::ofstream(dir / "huge.png", std::ios::binary) << png;
    try {
      ReadImage(dir / "huge.png");
      FAIL();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("huge.png: the header claims 100000x100000 pixels"), std::string::npos)
          << e.what();
    }
  }
  // No temporary files are left behind.
  for (const auto& e : fs::directory_iterator(dir)) {
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  }
}

// Issue 19: a 347-byte EXR whose capDate attribute claims 1.9 GB made OpenEXR allocate
// 2 GB (24 s) before failing; the header walk refuses it before OpenImageIO opens it.
TEST(ImageIo, ExrAttributeLargerThanTheFileIsRefusedFirst) {
  const fs::path regressions = fs::path(CREASE_TEST_DIR) / "../fuzz/regressions";
  const std::string e = testing::ErrorOf([&] { ReadImage(regressions / "exr_fuzzer/attribute_claims_2gb.exr"); });
  EXPECT_NE(e.find("attribute_claims_2gb.exr: EXR attribute 'capDate' (string) claims 1946157075 bytes"),
            std::string::npos) << e;
  // A data window beyond 10^8 pixels: a valid file with its dataWindow's xMax raised.
  const fs::path dir = ::crease::testing::TestDir() / "crease_image_io";
  const fs::path good = dir / "window.exr";
  WriteImage(good, RandomImage(4, 4, 1, 3));
  std::string bytes = ReadFileToString(good);
  const size_t at = bytes.find("dataWindow");
  ASSERT_NE(at, std::string::npos);
  const size_t x_max = at + std::string("dataWindow").size() + 1 + std::string("box2i").size() + 1 + 4 + 8;
  const int32_t huge = 2'000'000'000;
  std::memcpy(&bytes[x_max], &huge, 4);
  const fs::path wide = dir / "window_wide.exr";
  std::ofstream(wide, std::ios::binary) << bytes;
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(wide); }).find("data window claims 2000000001x4 pixels"), std::string::npos);
  EXPECT_EQ(ReadImage(good).rows, 4);  // the walk accepts crease's own files
  // Fuzzing (2026-12-05): a 298-byte EXR whose data window is 6553604×2 (13 M pixels,
  // within 10^8) made OpenEXR allocate 5 GB of row buffers; each side is bounded too.
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(regressions / "exr_fuzzer/wide_data_window.exr"); })
                .find("wide_data_window.exr: the EXR data window claims 6553604x2 pixels (crease reads 1 to 32768 per side"),
            std::string::npos);
  // The walk reads each value as OpenEXR does, not by the size the header states: a
  // channel list longer than stated hid a 10065565-pixel wide data window from it.
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(regressions / "exr_fuzzer/chlist_longer_than_stated.exr"); })
                .find("EXR attribute 'channels' (chlist) claims 55 bytes, but its value holds 99"),
            std::string::npos);
  // A preview of 4294967279×2 pixels: 4·w·h overflowed 64 bits in the walk (UBSan).
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(regressions / "exr_fuzzer/preview_size_overflow.exr"); })
                .find("(preview) claims 0 bytes, but its value runs past the end of the file"),
            std::string::npos);
  {
    std::string wrong = bytes;
    const size_t c = wrong.find("compression");
    ASSERT_NE(c, std::string::npos);
    wrong[c + 2 * std::string("compression").size() + 2] = '\x02';  // its size, 1 for the type
    std::ofstream(dir / "compression_size.exr", std::ios::binary) << wrong;
    EXPECT_NE(testing::ErrorOf([&] { ReadImage(dir / "compression_size.exr"); })
                  .find("'compression' (compression) claims 2 bytes, but its value holds 1"),
              std::string::npos);
  }
  // A tile of 65536² pixels: a `tiles` attribute put first in crease's own header.
  std::string tiled = bytes.substr(0, 8) + std::string("tiles\0tiledesc\0", 15);
  const uint32_t tile_desc[2] = {65536, 65536};
  tiled += std::string("\x09\0\0\0", 4) + std::string(reinterpret_cast<const char*>(tile_desc), 8) + '\0';
  std::memcpy(&bytes[x_max], "\x03\0\0\0", 4);  // the data window back to 4×4
  tiled += bytes.substr(8);
  std::ofstream(dir / "tiled.exr", std::ios::binary) << tiled;
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(dir / "tiled.exr"); }).find("tiled.exr: the EXR tiles claim 65536x65536"),
            std::string::npos);
}

// Fuzzing (2026-12-05): a 163-byte PNG whose tEXt chunk claims 2.1 GB made libpng
// allocate 2.1 GB; the chunk walk refuses a chunk longer than the rest of the file.
TEST(ImageIo, PngChunkLargerThanTheFileIsRefusedFirst) {
  const fs::path bad = fs::path(CREASE_TEST_DIR) / "../fuzz/regressions/png_fuzzer/chunk_claims_2gb.png";
  const std::string e = testing::ErrorOf([&] { ReadImage(bad); });
  EXPECT_NE(e.find("chunk_claims_2gb.png: PNG chunk 'tEXt' claims 2113929238 bytes, but the file has"),
            std::string::npos) << e;
  // Crease's own PNGs pass the walk; one cut inside its last chunk does not.
  const fs::path dir = ::crease::testing::TestDir() / "crease_image_png_chunks";
  fs::create_directories(dir);
  WriteImage(dir / "ok.png", RandomImage(5, 7, 3, 4));
  EXPECT_EQ(ReadImage(dir / "ok.png").cols, 7);
  std::string png = ReadFileToString(dir / "ok.png");
  std::ofstream(dir / "cut.png", std::ios::binary) << png.substr(0, png.size() - 2);
  EXPECT_NE(testing::ErrorOf([&] { ReadImage(dir / "cut.png"); }).find("cut.png: PNG chunk 'IEND' claims 0 bytes"),
            std::string::npos);
}

// Issue 19: onto a full disk, `synth render -o r.png` exited 0 and left a truncated
// PNG (OIIO's PNG writer does not report the failed write). A file size limit
// (RLIMIT_FSIZE, each ctest test is its own process) stands in for the full disk:
// every format must throw, naming the file, and leave neither it nor a temporary.
TEST(ImageIo, FullDiskIsAnErrorAndLeavesNoFile) {
  const fs::path dir = ::crease::testing::TestDir() / "crease_image_full";
  fs::create_directories(dir);
  const cv::Mat noise = RandomImage(240, 320, 3, 9);
  std::signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead of killing the process
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  rlimit small = old;
  small.rlim_cur = 16 * 1024;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  std::vector<std::string> errors;
  for (const char* name : {"r.png", "r.exr", "r.tif"}) {
    try {
      WriteImage(dir / name, noise);
      errors.push_back("");
    } catch (const Error& e) {
      errors.push_back(e.what());
    }
  }
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old), 0);
  for (size_t i = 0; i < errors.size(); ++i) {
    EXPECT_NE(errors[i].find("crease_image_full/r."), std::string::npos) << i << ": " << errors[i];
  }
  EXPECT_TRUE(fs::is_empty(dir)) << "a partial file or a temporary was left";
  // Below the limit the same write works.
  WriteImage(dir / "small.png", RandomImage(8, 8, 3, 1));
  EXPECT_TRUE(fs::is_regular_file(dir / "small.png"));
}

}  // namespace
}  // namespace crease
