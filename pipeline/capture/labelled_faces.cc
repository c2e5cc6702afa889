#include "pipeline/capture/labelled_faces.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/image_io.h"

namespace crease {

namespace fs = std::filesystem;

namespace {

std::vector<std::string> ImageNames(const fs::path& folder) {
  Require(fs::is_directory(folder), fmt::format("{}: not a folder of labelled faces", folder.string()));
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(folder)) {
    if (e.is_regular_file() && e.path().extension() == ".png") names.push_back(e.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

MatX2d ReadPts(const fs::path& path) {
  std::ifstream in(path);
  Require(in.good(), fmt::format("{}: missing landmark file (iBUG .pts)", path.string()));
  std::string line;
  int n = -1;
  while (std::getline(in, line)) {
    if (line.rfind("n_points:", 0) == 0) {
      try {
        n = std::stoi(line.substr(9));
      } catch (const std::exception&) {
        throw Error(fmt::format("{}: 'n_points:' is not followed by a number", path.string()));
      }
    }
    if (line.find('{') != std::string::npos) break;
  }
  Require(n == 68, fmt::format("{}: expected 'n_points: 68' before '{{' (got {})", path.string(), n));
  MatX2d p(68, 2);
  for (int i = 0; i < 68; ++i) {
    Require(static_cast<bool>(in >> p(i, 0) >> p(i, 1)),
            fmt::format("{}: point {} is missing or not two numbers", path.string(), i + 1));
  }
  Require(p.allFinite(), fmt::format("{}: non-finite coordinates", path.string()));
  return p;
}

void WriteLabelledFaces(const fs::path& folder, const std::vector<LabelledFace>& faces) {
  fs::create_directories(folder);
  for (const LabelledFace& f : faces) {
    WriteImage(folder / (f.name + ".png"), f.image, {.srgb = false});
    const fs::path pts = folder / (f.name + ".pts");
    const fs::path tmp = folder / (f.name + ".pts.tmp");
    {
      std::ofstream out(tmp);
      out << "version: 1\nn_points: " << f.landmarks.rows() << "\n{\n";
      for (int i = 0; i < f.landmarks.rows(); ++i) out << fmt::format("{:.4f} {:.4f}\n", f.landmarks(i, 0), f.landmarks(i, 1));
      out << "}\n";
      Require(out.good(), fmt::format("{}: cannot write", tmp.string()));
    }
    fs::rename(tmp, pts);
  }
}

std::vector<LabelledFace> ReadLabelledFaces(const fs::path& folder) {
  if (fs::is_regular_file(folder) && folder.extension() == ".xml") return ReadDlibXmlFaces(folder);
  std::vector<LabelledFace> out;
  for (const std::string& name : ImageNames(folder)) {
    LabelledFace f;
    f.name = name;
    const cv::Mat raw = ReadImage(folder / (name + ".png"), /*srgb=*/false);  // value / 255
    Require(raw.channels() == 3 || raw.channels() == 1,
            fmt::format("{}: expected a gray or RGB image", (folder / (name + ".png")).string()));
    raw.convertTo(f.image, CV_MAKETYPE(CV_8U, raw.channels()), 255.0);
    f.landmarks = ReadPts(folder / (name + ".pts"));
    out.push_back(std::move(f));
  }
  Require(!out.empty(), fmt::format("{}: no NAME.png + NAME.pts pairs", folder.string()));
  return out;
}

namespace {

// One tag of an XML file: its name ("/box" for a closing tag) and attributes.
struct XmlTag {
  std::string name;
  std::vector<std::pair<std::string, std::string>> attributes;
  int line = 0;
  const std::string* Find(const std::string& key) const {
    for (const auto& [k, v] : attributes) {
      if (k == key) return &v;
    }
    return nullptr;
  }
};

// The tags of a small XML dialect (no entities, CDATA or nesting in attributes),
// enough for dlib's imglab files; comments, declarations and text are skipped.
std::vector<XmlTag> XmlTags(const std::string& text, const std::string& what) {
  std::vector<XmlTag> tags;
  size_t i = 0;
  int line = 1;
  auto advance_to = [&](size_t j) {
    line += static_cast<int>(std::count(text.begin() + static_cast<std::ptrdiff_t>(i),
                                        text.begin() + static_cast<std::ptrdiff_t>(j), '\n'));
    i = j;
  };
  while (true) {
    const size_t open = text.find('<', i);
    if (open == std::string::npos) break;
    advance_to(open);
    if (text.compare(open, 4, "<!--") == 0) {
      const size_t end = text.find("-->", open);
      Require(end != std::string::npos, fmt::format("{}:{}: unterminated comment", what, line));
      advance_to(end + 3);
      continue;
    }
    const size_t close = text.find('>', open);
    Require(close != std::string::npos, fmt::format("{}:{}: unterminated tag", what, line));
    XmlTag tag;
    tag.line = line;
    const std::string body = text.substr(open + 1, close - open - 1);
    advance_to(close + 1);
    if (body.empty() || body[0] == '?' || body[0] == '!') continue;
    size_t k = 0;
    while (k < body.size() && !std::isspace(static_cast<unsigned char>(body[k])) && body[k] != '/') ++k;
    tag.name = body.substr(0, k);
    if (tag.name.empty() && !body.empty() && body[0] == '/') {
      size_t e = 1;
      while (e < body.size() && !std::isspace(static_cast<unsigned char>(body[e]))) ++e;
      tag.name = body.substr(0, e);
      tags.push_back(std::move(tag));
      continue;
    }
    while (k < body.size()) {
      while (k < body.size() && (std::isspace(static_cast<unsigned char>(body[k])) || body[k] == '/')) ++k;
      if (k >= body.size()) break;
      const size_t eq = body.find('=', k);
      Require(eq != std::string::npos && eq + 1 < body.size() && (body[eq + 1] == '\'' || body[eq + 1] == '"'),
              fmt::format("{}:{}: malformed attribute in <{}>", what, tag.line, tag.name));
      const char quote = body[eq + 1];
      const size_t end = body.find(quote, eq + 2);
      Require(end != std::string::npos, fmt::format("{}:{}: unterminated attribute value in <{}>", what, tag.line, tag.name));
      std::string key = body.substr(k, eq - k);
      while (!key.empty() && std::isspace(static_cast<unsigned char>(key.back()))) key.pop_back();
      tag.attributes.emplace_back(key, body.substr(eq + 2, end - eq - 2));
      k = end + 1;
    }
    tags.push_back(std::move(tag));
  }
  return tags;
}

// Coordinates of a dlib XML file beyond this (pixels) are refused as corrupt.
constexpr double kMaxXmlCoordinate = 1e6;

double XmlNumber(const XmlTag& tag, const std::string& key, const std::string& what) {
  const std::string* v = tag.Find(key);
  Require(v != nullptr, fmt::format("{}:{}: <{}> has no '{}'", what, tag.line, tag.name, key));
  try {
    size_t used = 0;
    const double x = std::stod(*v, &used);
    if (used != v->size() || !std::isfinite(x)) throw std::invalid_argument("trailing");
    return x;
  } catch (const std::exception&) {
    throw Error(fmt::format("{}:{}: <{}> {}='{}' is not a number", what, tag.line, tag.name, key, *v));
  }
}

std::string ReadWholeFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  Require(in.good(), fmt::format("{}: cannot open", path.string()));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// An image file as 8-bit RGB (gray and RGBA converted).
cv::Mat ReadRgb8(const fs::path& path) {
  const cv::Mat raw = ReadImage(path, /*srgb=*/false);
  cv::Mat rgb = raw, out;
  if (raw.channels() == 1) cv::cvtColor(raw, rgb, cv::COLOR_GRAY2RGB);
  if (raw.channels() == 4) cv::cvtColor(raw, rgb, cv::COLOR_RGBA2RGB);
  rgb.convertTo(out, CV_8UC3, 255.0);
  return out;
}

// The square crop of `image` around box tag `b` (format in labelled_faces.h) with
// the box's 68 `parts` moved into it.
LabelledFace CropBox(const cv::Mat& image, const XmlTag& b, const MatX2d& parts, const DlibXmlOptions& options,
                     const std::string& what) {
  const double top = XmlNumber(b, "top", what), left = XmlNumber(b, "left", what);
  const double width = XmlNumber(b, "width", what), height = XmlNumber(b, "height", what);
  Require(width > 0 && height > 0, fmt::format("{}:{}: <box> has an empty size", what, b.line));
  const double side = std::max(width, height);
  // Issue 19 (dlib_xml_fuzzer): a box of 1e-300 px scaled the crop by 1e302 (infinite coordinates).
  Require(side >= 1.0 && side <= kMaxXmlCoordinate && std::abs(top) <= kMaxXmlCoordinate &&
              std::abs(left) <= kMaxXmlCoordinate && parts.cwiseAbs().maxCoeff() <= kMaxXmlCoordinate,
          fmt::format("{}:{}: <box> smaller than 1 px, or a coordinate beyond ±{} px", what, b.line,
                      kMaxXmlCoordinate));
  const double s = options.box_px / side;
  const int crop = static_cast<int>(std::lround(options.crop_scale * options.box_px));
  const double cx = left + 0.5 * (width - 1.0), cy = top + 0.5 * (height - 1.0);
  // Pixel centres at integers: x' = s (x − cx) + (crop − 1) / 2.
  const double tx = 0.5 * (crop - 1) - s * cx, ty = 0.5 * (crop - 1) - s * cy;
  const cv::Mat M = (cv::Mat_<double>(2, 3) << s, 0.0, tx, 0.0, s, ty);
  LabelledFace face;
  cv::warpAffine(image, face.image, M, cv::Size(crop, crop), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  face.landmarks.resize(68, 2);
  for (int k = 0; k < 68; ++k) face.landmarks.row(k) << s * parts(k, 0) + tx, s * parts(k, 1) + ty;
  return face;
}

// The part index of a <part> tag (its name, 00 … 67), or -1 for other names.
int PartIndex(const XmlTag& tag, const std::string& what) {
  const std::string* name = tag.Find("name");
  Require(name != nullptr, fmt::format("{}:{}: <part> has no 'name'", what, tag.line));
  int k = -1;
  try {
    k = std::stoi(*name);
  } catch (const std::exception&) {
  }
  return k >= 0 && k < 68 ? k : -1;
}

// Walks the tags of one dlib XML file: the open <image> and <box>, and the parts
// read so far.
struct DlibXmlReader {
  DlibXmlReader(const fs::path& xml_path, const DlibXmlOptions& o) : xml(xml_path), options(o), what(xml_path.string()) {}

  const fs::path& xml;
  const DlibXmlOptions& options;
  std::string what;
  std::vector<LabelledFace> out;
  std::string image_file;
  cv::Mat image;  // 8-bit RGB of image_file, loaded on its first usable box
  bool image_loaded = false;
  int box_index = 0, boxes_seen = 0;
  const XmlTag* box = nullptr;
  MatX2d parts;
  std::vector<uint8_t> have;

  void Tag(const XmlTag& tag) {
    if (tag.name == "image") {
      const std::string* f = tag.Find("file");
      Require(f != nullptr, fmt::format("{}:{}: <image> has no 'file'", what, tag.line));
      image_file = *f;
      image_loaded = false;
      box_index = 0;
    } else if (tag.name == "box") {
      Require(!image_file.empty(), fmt::format("{}:{}: <box> outside an <image>", what, tag.line));
      box = &tag;
      parts = MatX2d::Zero(68, 2);
      have.assign(68, 0);
      ++boxes_seen;
    } else if (tag.name == "part" && box != nullptr) {
      const int k = PartIndex(tag, what);
      if (k < 0) return;
      parts(k, 0) = XmlNumber(tag, "x", what);
      parts(k, 1) = XmlNumber(tag, "y", what);
      have[static_cast<size_t>(k)] = 1;
    } else if (tag.name == "/box" && box != nullptr) {
      CloseBox();
    }
  }

  void CloseBox() {
    const XmlTag& b = *box;
    box = nullptr;
    const int index = box_index++;
    const std::string* ignore = b.Find("ignore");
    if ((ignore != nullptr && *ignore == "1") || std::count(have.begin(), have.end(), 1) != 68) return;
    if (!image_loaded) {
      const fs::path path = xml.parent_path() / image_file;
      Require(fs::exists(path), fmt::format("{}:{}: image '{}' not found ({})", what, b.line, image_file, path.string()));
      image = ReadRgb8(path);
      image_loaded = true;
    }
    LabelledFace face = CropBox(image, b, parts, options, what);
    face.name = fmt::format("{}_{}", fs::path(image_file).stem().string(), index);
    out.push_back(std::move(face));
  }
};

}  // namespace

std::vector<LabelledFace> ReadDlibXmlFaces(const fs::path& xml, const DlibXmlOptions& options) {
  Require(options.crop_scale >= 1.0 && options.box_px >= 16,
          fmt::format("DlibXmlOptions: crop_scale = {} must be ≥ 1 and box_px = {} ≥ 16", options.crop_scale,
                      options.box_px));
  const std::vector<XmlTag> tags = XmlTags(ReadWholeFile(xml), xml.string());
  DlibXmlReader reader(xml, options);
  for (const XmlTag& tag : tags) reader.Tag(tag);
  Require(!reader.out.empty(), fmt::format("{}: no <box> with the 68 <part>s (00 … 67) among {} boxes", xml.string(),
                                           reader.boxes_seen));
  return std::move(reader.out);
}

}  // namespace crease
