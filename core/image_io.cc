#include "core/image_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <vector>
#include <fmt/format.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/file_util.h"

namespace crease {
namespace fs = std::filesystem;

namespace {
// The most pixels crease decodes from one image: 10^8, more than an 8192² texture or
// any camera frame (as 4-channel float, 1.6 GB). A header claiming more (a PNG of
// 100000×100000: 120 GB) is refused before anything is allocated (issue 19).
constexpr int64_t kMaxImagePixels = 100'000'000;
// The widest or tallest image crease decodes: 32768 pixels. Readers allocate buffers of
// whole rows (OpenEXR a block of 16 to 256 rows, twice), so a 298-byte EXR whose data
// window is 6553604×2 (13 M pixels, within the bound above) made OpenEXR allocate 5 GB
// (issue 19, fuzz/regressions/exr_fuzzer/wide_data_window.exr).
constexpr int64_t kMaxImageSide = 32768;
// An EXR tile of at most 4096² pixels (OpenEXR allocates whole tiles per thread).
constexpr int64_t kMaxExrTilePixels = int64_t{4096} * 4096;

// Throws unless w×h is an image size crease reads (see the bounds above); `what`
// names the header field, e.g. "the EXR data window".
void CheckImageSize(const fs::path& path, const char* what, int64_t w, int64_t h) {
  if (w < 1 || h < 1 || w > kMaxImageSide || h > kMaxImageSide || w * h > kMaxImagePixels) {
    throw Error(fmt::format("{}: {} claims {}x{} pixels (crease reads 1 to {} per side, {} in all)", path.string(),
                            what, w, h, kMaxImageSide, kMaxImagePixels));
  }
}

bool IsFloatFormat(const std::string& ext) {
  return ext == ".exr" || ext == ".hdr" || ext == ".pfm";
}

// A NUL-terminated name or type of an EXR header attribute (at most 255 characters).
std::string ReadExrHeaderString(std::istream& in, const fs::path& path, const char* what) {
  std::string s;
  for (char c; in.get(c);) {
    if (c == '\0') return s;
    if (s.size() == 255) {
      throw Error(fmt::format("{}: EXR header: an attribute {} longer than 255 bytes", path.string(), what));
    }
    s.push_back(c);
  }
  throw Error(fmt::format("{}: EXR header ends inside an attribute {}", path.string(), what));
}

// The bytes OpenEXR's reader takes for an attribute's value of `type`, which for
// most types is not the size the header states: fixed-size types read their own
// size, a channel list reads channels up to an empty name, a preview its width ×
// height × 4 pixels. -1: the stated size (strings, vectors, unknown types);
// kPastTheEnd: a value that would run past the end of the file. `in` stands at the
// value and is left there.
constexpr int64_t kPastTheEnd = std::numeric_limits<int64_t>::max();
int64_t ExrValueBytes(std::istream& in, const std::string& type, int64_t size) {
  static const std::map<std::string, int64_t> kFixed = {
      {"box2i", 16}, {"box2f", 16}, {"v2i", 8},  {"v2f", 8},   {"v2d", 16},  {"v3i", 12},
      {"v3f", 12},   {"v3d", 24},   {"int", 4},  {"float", 4}, {"double", 8}, {"compression", 1},
      {"lineOrder", 1}, {"envmap", 1}, {"deepImageState", 1}, {"tiledesc", 9}, {"rational", 8},
      {"keycode", 28}, {"timecode", 8}, {"chromaticities", 32}, {"m33f", 36}, {"m44f", 64},
      {"m33d", 72}, {"m44d", 128}};
  if (const auto it = kFixed.find(type); it != kFixed.end()) return it->second;
  if (type != "chlist" && type != "preview") return -1;
  const auto start = in.tellg();
  int64_t bytes = 0;
  if (type == "preview") {
    uint32_t wh[2] = {};
    in.read(reinterpret_cast<char*>(wh), 8);
    const uint64_t pixels = uint64_t{wh[0]} * wh[1];  // < 2^64; past 2^40 no file holds them
    bytes = in && pixels < (uint64_t{1} << 40) ? 8 + 4 * static_cast<int64_t>(pixels) : kPastTheEnd;
  } else {  // channels: a name (at most 255 characters and its NUL), then 16 bytes
    for (int64_t name = 1; in && name > 0;) {
      name = 0;
      for (char c; in.get(c) && c != '\0' && name < 256;) ++name;
      bytes += name + 1 + (name > 0 ? 16 : 0);
      if (name > 0) in.seekg(16, std::ios::cur);
    }
    if (!in) bytes = kPastTheEnd;
  }
  in.clear();
  in.seekg(start);
  return bytes;
}

// OpenEXR allocates a header attribute at the size its header states before reading
// it, so a 347-byte file whose string attribute claims 1.9 GB took 2 GB and 24 s to
// fail (issue 19, fuzz/regressions/exr_fuzzer). Before OpenImageIO opens an OpenEXR
// file (magic 76 2f 31 01; others pass), its header (every part's, for multi-part
// files) is walked as OpenEXR reads it: an attribute larger than the rest of the file,
// or whose stated size is not what OpenEXR reads for its type (ExrValueBytes: a
// 262-byte file whose channel list was longer than stated was read by OpenEXR with a
// 10065565-pixel wide data window the walk had not seen, fuzz/regressions/exr_fuzzer/
// chlist_longer_than_stated.exr), a name or type without its NUL, or a data window
// or tiles beyond the bounds above is an Error naming the file and the attribute.
// `in` stands after the magic; `file_size` is the file's length.
void CheckExrHeader(std::istream& in, const fs::path& path, int64_t file_size) {
  uint32_t version = 0;
  if (!in.read(reinterpret_cast<char*>(&version), 4)) {
    throw Error(fmt::format("{}: EXR file ends in its version field", path.string()));
  }
  const bool multipart = (version & 0x1000u) != 0;
  for (bool part_empty = false; !part_empty;) {
    part_empty = true;
    for (std::string name; !(name = ReadExrHeaderString(in, path, "name")).empty();) {
      part_empty = false;
      const std::string type = ReadExrHeaderString(in, path, "type");
      int32_t size = 0;
      if (!in.read(reinterpret_cast<char*>(&size), 4)) {
        throw Error(fmt::format("{}: EXR header ends in the size of attribute '{}'", path.string(), name));
      }
      const int64_t rest = file_size - static_cast<int64_t>(in.tellg());
      if (size < 0 || size > rest) {
        throw Error(fmt::format("{}: EXR attribute '{}' ({}) claims {} bytes, but the file has {} left",
                                path.string(), name, type, size, rest));
      }
      if (const int64_t bytes = ExrValueBytes(in, type, size); bytes >= 0 && bytes != size) {
        throw Error(fmt::format("{}: EXR attribute '{}' ({}) claims {} bytes, but its value {}", path.string(), name,
                                type, size,
                                bytes == kPastTheEnd ? "runs past the end of the file" : fmt::format("holds {}", bytes)));
      }
      // ExrValueBytes has checked the sizes of box2i (16) and tiledesc (9) values.
      if (name == "dataWindow" && type == "box2i") {
        int32_t box[4];
        in.read(reinterpret_cast<char*>(box), 16);
        CheckImageSize(path, "the EXR data window", int64_t{box[2]} - box[0] + 1, int64_t{box[3]} - box[1] + 1);
      } else if (name == "tiles" && type == "tiledesc") {
        uint32_t tile[2];
        in.read(reinterpret_cast<char*>(tile), 8).seekg(1, std::ios::cur);  // past the level mode
        if (tile[0] < 1 || tile[1] < 1 || int64_t{tile[0]} * tile[1] > kMaxExrTilePixels) {
          throw Error(fmt::format("{}: the EXR tiles claim {}x{} pixels each (1 to {} are read)", path.string(),
                                  tile[0], tile[1], kMaxExrTilePixels));
        }
      } else {
        in.seekg(size, std::ios::cur);
      }
    }
    if (!multipart) break;
  }
}

// libpng allocates a chunk at the length its header states before reading it (the
// Debian build sets no limit), so a 163-byte PNG whose tEXt chunk claimed 2.1 GB
// allocated 2.1 GB (issue 19, fuzz/regressions/png_fuzzer/chunk_claims_2gb.png).
// Before OpenImageIO opens a PNG (its 8-byte signature; others pass), its chunks are
// walked up to IEND: a chunk longer than the rest of the file is an Error naming the
// file and the chunk. A file that ends between chunks is left to libpng's error.
// `in` stands after the signature; `file_size` is the file's length.
void CheckPngChunks(std::istream& in, const fs::path& path, int64_t file_size) {
  for (unsigned char head[8]; in.read(reinterpret_cast<char*>(head), 8);) {
    const int64_t length = int64_t{head[0]} << 24 | int64_t{head[1]} << 16 | int64_t{head[2]} << 8 | head[3];
    std::string type(head + 4, head + 8);
    for (char& c : type) c = std::isalpha(static_cast<unsigned char>(c)) ? c : '?';
    const int64_t rest = file_size - static_cast<int64_t>(in.tellg());
    if (length + 4 > rest) {  // the data and its CRC
      throw Error(fmt::format("{}: PNG chunk '{}' claims {} bytes, but the file has {} left", path.string(), type,
                              length, std::max<int64_t>(rest - 4, 0)));
    }
    if (type == "IEND") return;
    in.seekg(length + 4, std::ios::cur);
  }
}

// Opens the file once and walks its header if it is an OpenEXR (magic 76 2f 31 01) or
// PNG (8-byte signature) file; other formats pass to OpenImageIO unchecked.
void CheckHeaderBeforeDecoding(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[8] = {};
  in.read(magic, 8);
  const std::streamsize got = in.gcount();
  const int64_t file_size = static_cast<int64_t>(fs::file_size(path));
  if (got >= 4 && std::memcmp(magic, "\x76\x2f\x31\x01", 4) == 0) {
    in.clear();
    in.seekg(4);
    CheckExrHeader(in, path, file_size);
  } else if (got == 8 && std::memcmp(magic, "\x89PNG\r\n\x1a\n", 8) == 0) {
    CheckPngChunks(in, path, file_size);
  }
}

// Encodes `data` (CV_32F, continuous) as `spec` with `out`, opened as `name`; errors
// name `path`.
void Encode(OIIO::ImageOutput& out, const std::string& name, const OIIO::ImageSpec& spec, const cv::Mat& data,
            const fs::path& path) {
  if (!out.open(name, spec)) {
    throw Error(fmt::format("{}: cannot open for writing: {}", path.string(), out.geterror()));
  }
  if (!out.write_image(OIIO::TypeDesc::FLOAT, data.data)) {
    throw Error(fmt::format("{}: write failed: {}", path.string(), out.geterror()));
  }
  if (!out.close()) {
    throw Error(fmt::format("{}: write failed: {}", path.string(), out.geterror()));
  }
}

// An 8- or 16-bit image's pixels as linear float, alpha kept: each code's value is
// OIIO's own conversion to float (what read_image would give), sRGB-decoded once
// into a table instead of once per pixel; the same floats as decoding every pixel.
template <typename T>
cv::Mat ReadSrgbIntegerImage(OIIO::ImageInput* in, const fs::path& path) {
  const OIIO::ImageSpec& spec = in->spec();
  const int w = spec.width, h = spec.height, c = spec.nchannels;
  const OIIO::TypeDesc type = OIIO::BaseTypeFromC<T>::value;
  std::vector<T> codes(static_cast<size_t>(w) * h * c);
  if (!in->read_image(0, 0, 0, c, type, codes.data())) {
    const std::string err = in->geterror();
    throw Error(fmt::format("{}: cannot decode image data: {}", path.string(), err));
  }
  const size_t levels = size_t{std::numeric_limits<T>::max()} + 1;
  std::vector<float> linear(levels), alpha(levels);
  for (size_t k = 0; k < levels; ++k) {
    const T code = static_cast<T>(k);
    OIIO::convert_pixel_values(type, &code, OIIO::TypeDesc::FLOAT, &alpha[k], 1);
    linear[k] = SrgbToLinear(alpha[k]);
  }
  const int color_channels = std::min(c, 3);  // alpha stays linear
  cv::Mat img(h, w, CV_32FC(c));
  for (int y = 0; y < h; ++y) {
    float* row = img.ptr<float>(y);
    const T* src = codes.data() + static_cast<size_t>(y) * w * c;
    for (int i = 0; i < w * c; ++i) row[i] = (i % c < color_channels ? linear : alpha)[src[i]];
  }
  return img;
}

}  // namespace

cv::Mat ReadImage(const fs::path& path, bool srgb) {
  RequireReadableFile(path);
  CheckHeaderBeforeDecoding(path);
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) {
    throw Error(fmt::format("{}: cannot read image: {}", path.string(), OIIO::geterror()));
  }
  const OIIO::ImageSpec& spec = in->spec();
  const int w = spec.width, h = spec.height, c = spec.nchannels;
  if (w <= 0 || h <= 0 || c < 1 || c > 4) {
    throw Error(fmt::format("{}: unsupported image layout {}x{} with {} channels", path.string(),
                            w, h, c));
  }
  CheckImageSize(path, "the header", w, h);
  const bool uniform = spec.channelformats.empty();
  if (srgb && uniform && spec.format == OIIO::TypeDesc::UINT8) return ReadSrgbIntegerImage<uint8_t>(in.get(), path);
  if (srgb && uniform && spec.format == OIIO::TypeDesc::UINT16) return ReadSrgbIntegerImage<uint16_t>(in.get(), path);
  cv::Mat img(h, w, CV_32FC(c));
  if (!in->read_image(0, 0, 0, c, OIIO::TypeDesc::FLOAT, img.data)) {
    const std::string err = in->geterror();
    throw Error(fmt::format("{}: cannot decode image data: {}", path.string(), err));
  }
  const bool integer = spec.format.is_floating_point() == false;
  if (integer && srgb) {
    const int color_channels = std::min(c, 3);  // alpha stays linear
    for (int y = 0; y < h; ++y) {
      float* row = img.ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        for (int k = 0; k < color_channels; ++k) row[x * c + k] = SrgbToLinear(row[x * c + k]);
      }
    }
  }
  return img;
}

void WriteImage(const fs::path& path, const cv::Mat& image, const ImageWriteOptions& options) {
  Require(!image.empty(), fmt::format("{}: refusing to write an empty image", path.string()));
  const int c = image.channels();
  Require(c >= 1 && c <= 4,
          fmt::format("{}: cannot write an image with {} channels", path.string(), c));
  Require(image.depth() == CV_32F || image.depth() == CV_8U,
          fmt::format("{}: images must be CV_32F or CV_8U", path.string()));
  Require(options.bits == 8 || options.bits == 16,
          fmt::format("{}: ImageWriteOptions.bits must be 8 or 16", path.string()));
  const std::string ext = LowerExtension(path);
  cv::Mat data;
  image.convertTo(data, CV_32F, image.depth() == CV_8U ? 1.0 / 255.0 : 1.0);
  data = data.isContinuous() ? data : data.clone();

  OIIO::TypeDesc format;
  if (IsFloatFormat(ext)) {
    format = options.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT;
  } else {
    format = options.bits == 16 ? OIIO::TypeDesc::UINT16 : OIIO::TypeDesc::UINT8;
    if (!cv::checkRange(data)) {
      throw Error(fmt::format("{}: image has NaN or infinite values; cannot store them in {}",
                              path.string(), ext));
    }
    if (options.srgb && image.depth() == CV_32F) {
      const int color_channels = std::min(c, 3);
      for (int y = 0; y < data.rows; ++y) {
        float* row = data.ptr<float>(y);
        for (int x = 0; x < data.cols; ++x) {
          for (int k = 0; k < color_channels; ++k) row[x * c + k] = LinearToSrgb(row[x * c + k]);
        }
      }
    }
  }
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out) {
    throw Error(fmt::format("{}: no image writer for extension '{}': {}", path.string(), ext, OIIO::geterror()));
  }
  OIIO::ImageSpec spec(data.cols, data.rows, c, format);
  // A fixed date: OpenEXR writers stamp the current time otherwise, and the same
  // inputs must give the same bytes (determinism, DESIGN.md).
  spec.attribute("DateTime", "1970:01:01 00:00:00");
  if (format == OIIO::TypeDesc::UINT8 || format == OIIO::TypeDesc::UINT16) {
    spec.attribute("oiio:ColorSpace", options.srgb ? "sRGB" : "Linear");
  }
  if (out->supports("ioproxy")) {
    // Encoded in memory, then written through a checked stream: OIIO's PNG writer
    // does not report a full disk (a truncated PNG was reported as written, issue 19).
    std::vector<unsigned char> bytes;
    OIIO::Filesystem::IOVecOutput memory(bytes);
    Require(out->set_ioproxy(&memory), fmt::format("{}: cannot encode in memory: {}", path.string(), out->geterror()));
    Encode(*out, path.string(), spec, data, path);
    WriteFileAtomic(path, [&](std::ostream& file) {
      file.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    });
  } else {
    WriteFileAtomicVia(path, [&](const fs::path& tmp) { Encode(*out, tmp.string(), spec, data, path); });
  }
}

}  // namespace crease
