#include "core/vtp_check.h"

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string_view>
#include <vector>
#include <fmt/format.h>
#include <zlib.h>

#include "core/error.h"

namespace crease {
namespace {

constexpr size_t npos = std::string_view::npos;
// deflate's largest compression ratio (1032:1, zlib's technical details): zlib (and
// LZ4, at most 255:1) data cannot inflate to more than this times its own size, and
// no inline or base64 array holds more than this many bytes per byte of file.
constexpr uint64_t kMaxInflation = 1032;
// LZMA's ratio has no such tight bound (xz packs zeros about 7000:1); this one is
// generous and still keeps a lying block header from asking for gigabytes.
constexpr uint64_t kMaxLzmaInflation = 1 << 16;
// The largest element count or number of components: VTK and crease index meshes
// with 32-bit ints.
constexpr uint64_t kMaxCount = std::numeric_limits<int32_t>::max();

[[noreturn]] void Malformed(const std::string& file, const std::string& what) {
  throw Error(fmt::format("{}: not a readable VTK XML PolyData file: {}", file, what));
}

uint64_t SaturatingProduct(uint64_t a, uint64_t b) {
  uint64_t product = 0;
  return __builtin_mul_overflow(a, b, &product) ? std::numeric_limits<uint64_t>::max() : product;
}

// An XML tag: its element name ("/Piece" for an end tag) and attributes.
struct Tag {
  std::string name;
  std::map<std::string, std::string, std::less<>> attributes;
  bool self_closing = false;
  size_t end = 0;  // offset just after '>'
};

// Reads the tag whose '<' is at `begin`; nullopt when it is not well formed (VTK reports that).
std::optional<Tag> ReadTag(std::string_view xml, size_t begin) {
  const size_t close = xml.find('>', begin);
  if (close == npos) return std::nullopt;
  std::string_view body = xml.substr(begin + 1, close - begin - 1);
  Tag tag;
  tag.end = close + 1;
  if (!body.empty() && body.back() == '/') {
    tag.self_closing = true;
    body.remove_suffix(1);
  }
  constexpr const char* kSpace = " \t\r\n";
  size_t i = body.find_first_of(kSpace);
  tag.name = body.substr(0, i);
  while ((i = body.find_first_not_of(kSpace, i)) != npos) {
    const size_t eq = body.find('=', i);
    if (eq == npos) return std::nullopt;
    std::string_view key = body.substr(i, eq - i);
    key = key.substr(0, key.find_last_not_of(kSpace) + 1);
    const size_t quote = body.find_first_not_of(kSpace, eq + 1);
    if (quote == npos || (body[quote] != '"' && body[quote] != '\'')) return std::nullopt;
    const size_t quote_end = body.find(body[quote], quote + 1);
    if (quote_end == npos) return std::nullopt;
    tag.attributes[std::string(key)] = std::string(body.substr(quote + 1, quote_end - quote - 1));
    i = quote_end + 1;
  }
  return tag;
}

// The count attribute `key` of `tag` (`fallback` when absent), within [0, kMaxCount].
uint64_t Count(const Tag& tag, std::string_view key, uint64_t fallback, const std::string& file) {
  const auto it = tag.attributes.find(key);
  if (it == tag.attributes.end()) return fallback;
  const std::string& s = it->second;
  uint64_t value = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  if (s.empty() || ec != std::errc() || end != s.data() + s.size() || value > kMaxCount) {
    Malformed(file, fmt::format("{} {}=\"{}\" is not a count from 0 to {}", tag.name, key, s, kMaxCount));
  }
  return value;
}

// What the XML header says about one DataArray.
struct ArrayClaim {
  std::string name;
  std::string parent;        // the enclosing element: "Points", "PointData", "Polys", ...
  int piece = 0;             // index of the enclosing Piece
  uint64_t type_size = 1;    // bytes per value (0: String, Bit; not checked)
  uint64_t bytes = 0;        // at least this many decoded bytes (tuples × components × type size)
  bool appended = false;     // format="appended": the data is at `offset` in the appended data
  bool ascii = false;        // format="ascii"
  uint64_t offset = 0;
  size_t inline_begin = 0;   // otherwise: the text inside the element
  size_t inline_size = 0;
};

// The header facts that the arrays are checked against.
struct VtpLayout {
  std::vector<ArrayClaim> arrays;
  uint64_t header_width = 4;   // header_type UInt32 or UInt64
  bool compressed = false;
  std::string compressor;      // "vtkZLibDataCompressor", "vtkLZ4DataCompressor", "vtkLZMADataCompressor"
  bool big_endian = false;
  bool raw = true;             // AppendedData encoding="raw" (else base64)
  size_t appended = npos;      // offset of the first appended byte, just after '_'
};

// The counts of the Piece being read.
struct PieceCounts {
  uint64_t points = 0;
  std::map<std::string, uint64_t, std::less<>> cells;  // "Verts", "Lines", "Strips", "Polys"
  uint64_t total_cells() const {
    uint64_t n = 0;
    for (const auto& [kind, count] : cells) n += count;
    return n;
  }
};

uint64_t TypeSize(const std::string& type) {
  static const std::map<std::string, uint64_t, std::less<>> sizes = {
      {"Int8", 1},  {"UInt8", 1},  {"Int16", 2},   {"UInt16", 2},  {"Int32", 4},
      {"UInt32", 4}, {"Int64", 8}, {"UInt64", 8}, {"Float32", 4}, {"Float64", 8}};
  const auto it = sizes.find(type);
  return it == sizes.end() ? 0 : it->second;  // String, Bit: not checked
}

// The tuples VTK allocates for a DataArray inside element `parent` (0 when VTK
// sizes it from the data, e.g. cell connectivity).
uint64_t Tuples(const Tag& array, const std::string& parent, const PieceCounts& piece,
                const std::string& file) {
  if (parent == "Points" || parent == "PointData") return piece.points;
  if (parent == "CellData") return piece.total_cells();
  if (parent == "FieldData") return Count(array, "NumberOfTuples", 0, file);
  const auto cells = piece.cells.find(parent);
  const auto name = array.attributes.find("Name");
  if (cells != piece.cells.end() && name != array.attributes.end() && name->second == "offsets") {
    return cells->second;
  }
  return 0;
}

ArrayClaim Claim(const Tag& array, std::string_view xml, const std::string& parent, int piece_index,
                 const PieceCounts& piece, const std::string& file) {
  ArrayClaim claim;
  const auto name = array.attributes.find("Name");
  claim.name = name == array.attributes.end() ? parent : name->second;
  claim.parent = parent;
  claim.piece = piece_index;
  const auto type = array.attributes.find("type");
  claim.type_size = TypeSize(type == array.attributes.end() ? "" : type->second);
  const uint64_t components = Count(array, "NumberOfComponents", 1, file);
  claim.bytes = SaturatingProduct(SaturatingProduct(Tuples(array, parent, piece, file), components),
                                  claim.type_size);
  const auto format = array.attributes.find("format");
  claim.appended = format != array.attributes.end() && format->second == "appended";
  claim.ascii = format != array.attributes.end() && format->second == "ascii";
  if (claim.appended) {
    claim.offset = Count(array, "offset", 0, file);
  } else if (!array.self_closing) {
    const size_t text_end = xml.find('<', array.end);
    claim.inline_begin = array.end;
    claim.inline_size = (text_end == npos ? xml.size() : text_end) - array.end;
  }
  return claim;
}

// Reads the XML header up to the appended data.
VtpLayout ReadLayout(std::string_view xml, const std::string& file) {
  VtpLayout layout;
  std::vector<std::string> open;  // enclosing elements
  PieceCounts piece;
  int piece_index = -1;
  size_t pos = 0;
  while ((pos = xml.find('<', pos)) != npos) {
    if (xml.compare(pos, 2, "<?") == 0 || xml.compare(pos, 2, "<!") == 0) {
      pos = xml.find('>', pos);
      continue;
    }
    const std::optional<Tag> tag = ReadTag(xml, pos);
    if (!tag || tag->name.empty()) break;
    pos = tag->end;
    if (tag->name[0] == '/') {
      if (!open.empty()) open.pop_back();
      continue;
    }
    if (tag->name == "VTKFile") {
      const auto header = tag->attributes.find("header_type");
      layout.header_width = header != tag->attributes.end() && header->second == "UInt64" ? 8 : 4;
      const auto compressor = tag->attributes.find("compressor");
      layout.compressed = compressor != tag->attributes.end() && !compressor->second.empty();
      if (layout.compressed) layout.compressor = compressor->second;
      const auto order = tag->attributes.find("byte_order");
      layout.big_endian = order != tag->attributes.end() && order->second == "BigEndian";
    } else if (tag->name == "Piece") {
      ++piece_index;
      piece.points = Count(*tag, "NumberOfPoints", 0, file);
      for (const char* kind : {"Verts", "Lines", "Strips", "Polys"}) {
        piece.cells[kind] = Count(*tag, std::string("NumberOf") + kind, 0, file);
      }
    } else if (tag->name == "DataArray") {
      layout.arrays.push_back(Claim(*tag, xml, open.empty() ? "" : open.back(), piece_index, piece, file));
    } else if (tag->name == "AppendedData") {
      const auto encoding = tag->attributes.find("encoding");
      layout.raw = encoding == tag->attributes.end() || encoding->second == "raw";
      const size_t underscore = xml.find('_', tag->end);
      if (underscore != npos) layout.appended = underscore + 1;
      break;  // binary from here on
    }
    if (!tag->self_closing) open.push_back(tag->name);
  }
  return layout;
}

// An unsigned integer of `width` bytes at `at` (the caller checked the bounds).
uint64_t ReadUInt(std::string_view bytes, size_t at, uint64_t width, bool big_endian) {
  uint64_t value = 0;
  for (uint64_t k = 0; k < width; ++k) {
    const auto byte = static_cast<unsigned char>(bytes[at + (big_endian ? k : width - 1 - k)]);
    value = value << 8 | byte;
  }
  return value;
}

// Where the data of one array lies and how large it is decoded.
struct HeldData {
  uint64_t bytes = 0;             // decoded bytes (an upper bound unless raw appended)
  bool exact = false;             // raw appended: `bytes` and the last block are known
  size_t last_block = 0;          // offset in the file of the last (compressed) block
  uint64_t last_block_size = 0;   // its size in the file
  uint64_t last_decoded_size = 0; // its size decoded
};

// The raw appended array at `at`, after checking that its header and data lie
// inside the file. Compressed: the header is [number of blocks, block size, last
// block size, compressed size of each block].
HeldData AppendedData(std::string_view bytes, size_t at, const VtpLayout& layout, const ArrayClaim& array,
                      const std::string& file) {
  const uint64_t w = layout.header_width;
  auto require_bytes = [&](uint64_t n, const std::string& what) {
    if (at > bytes.size() || n > bytes.size() - at) {
      Malformed(file, fmt::format("array '{}': {} past the end of the file", array.name, what));
    }
  };
  auto word = [&](uint64_t k) { return ReadUInt(bytes, at + k * w, w, layout.big_endian); };
  HeldData held{.exact = true};
  if (!layout.compressed) {
    require_bytes(w, "the size header is");
    require_bytes(w + std::min<uint64_t>(word(0), bytes.size()), fmt::format("{} bytes of data run", word(0)));
    held.bytes = held.last_block_size = held.last_decoded_size = word(0);
    held.last_block = at + w;
    return held;
  }
  require_bytes(3 * w, "the block header is");
  const uint64_t blocks = word(0), block_size = word(1), last_size = word(2);
  if (blocks == 0) return held;
  if (block_size == 0 || last_size > block_size) {
    Malformed(file, fmt::format("array '{}': bad compressed block sizes {} and {} (last)", array.name,
                                block_size, last_size));
  }
  require_bytes(SaturatingProduct(3 + blocks, w), fmt::format("the sizes of {} compressed blocks run", blocks));
  uint64_t compressed = 0;
  for (uint64_t k = 0; k < blocks; ++k) {
    held.last_block = at + (3 + blocks) * w + compressed;
    held.last_block_size = word(3 + k);
    compressed += std::min<uint64_t>(held.last_block_size, bytes.size());  // clamped: no overflow
    require_bytes((3 + blocks) * w + compressed, fmt::format("compressed block {} runs", k));
  }
  held.last_decoded_size = last_size > 0 ? last_size : block_size;
  held.bytes = SaturatingProduct(blocks - 1, block_size) + held.last_decoded_size;
  const uint64_t max_inflation =
      layout.compressor == "vtkLZMADataCompressor" ? kMaxLzmaInflation : kMaxInflation;
  if (held.bytes / max_inflation > compressed) {
    Malformed(file, fmt::format("array '{}': {} compressed bytes cannot hold the {} bytes its block header "
                                "claims", array.name, compressed, held.bytes));
  }
  return held;
}

// The decoded data the file holds for `array`.
HeldData Held(std::string_view bytes, const VtpLayout& layout, const ArrayClaim& array, const std::string& file) {
  // ascii: each value takes at least a character and a separator.
  if (array.ascii) return {.bytes = SaturatingProduct((array.inline_size + 1) / 2, array.type_size)};
  if (!array.appended) return {.bytes = SaturatingProduct(kMaxInflation, array.inline_size)};
  if (layout.appended == npos) {
    Malformed(file, fmt::format("array '{}' is in appended data, but the file has no AppendedData", array.name));
  }
  if (!layout.raw) return {.bytes = SaturatingProduct(kMaxInflation, bytes.size() - layout.appended)};
  if (array.offset > bytes.size() - layout.appended) {
    Malformed(file, fmt::format("array '{}': offset {} is past the end of the file", array.name, array.offset));
  }
  return AppendedData(bytes, layout.appended + array.offset, layout, array, file);
}

// The last value of an integer array, when it can be read without decoding the
// whole array (ascii, raw appended); nullopt otherwise.
std::optional<uint64_t> LastValue(std::string_view bytes, const VtpLayout& layout, const ArrayClaim& array,
                                  const HeldData& held, const std::string& file) {
  if (array.ascii) {
    std::string_view text = bytes.substr(array.inline_begin, array.inline_size);
    text = text.substr(0, text.find_last_not_of(" \t\r\n") + 1);
    text = text.substr(text.find_last_of(" \t\r\n") + 1);  // npos + 1 == 0
    uint64_t value = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
    return value;
  }
  const bool zlib = layout.compressor == "vtkZLibDataCompressor";
  if (!held.exact || (layout.compressed && !zlib) || array.type_size == 0 ||
      held.last_decoded_size < array.type_size) {
    return std::nullopt;  // other compressors: VTK's own checks
  }
  std::string block(held.last_decoded_size, '\0');
  if (layout.compressed) {
    uLongf size = block.size();
    if (uncompress(reinterpret_cast<Bytef*>(block.data()), &size,
                   reinterpret_cast<const Bytef*>(bytes.data() + held.last_block), held.last_block_size) != Z_OK ||
        size != block.size()) {
      Malformed(file, fmt::format("array '{}': its last compressed block does not inflate to {} bytes",
                                  array.name, block.size()));
    }
  } else {
    block = bytes.substr(held.last_block, held.last_block_size);
  }
  return ReadUInt(block, block.size() - array.type_size, array.type_size, layout.big_endian);
}

// VTK sizes a cell array's connectivity by the last of its offsets: that value
// must not exceed the connectivity values the file holds.
void CheckOffsets(std::string_view bytes, const VtpLayout& layout, const std::vector<HeldData>& held,
                  const std::string& file) {
  const auto& arrays = layout.arrays;
  for (size_t i = 0; i < arrays.size(); ++i) {
    if (arrays[i].name != "offsets") continue;
    for (size_t j = 0; j < arrays.size(); ++j) {
      if (arrays[j].name != "connectivity" || arrays[j].piece != arrays[i].piece ||
          arrays[j].parent != arrays[i].parent) {
        continue;
      }
      const std::optional<uint64_t> last = LastValue(bytes, layout, arrays[i], held[i], file);
      if (arrays[j].type_size == 0) continue;
      const uint64_t values = held[j].bytes / arrays[j].type_size;
      if (last && *last > values) {
        Malformed(file, fmt::format("{} offsets end at {}, but the connectivity holds {} values",
                                    arrays[i].parent, *last, values));
      }
    }
  }
}

}  // namespace

void CheckVtpSizes(const std::string& bytes, const std::string& file) {
  const VtpLayout layout = ReadLayout(bytes, file);
  std::vector<HeldData> held;
  for (const ArrayClaim& array : layout.arrays) {
    held.push_back(Held(bytes, layout, array, file));
    if (held.back().bytes < array.bytes) {
      Malformed(file, fmt::format("array '{}' holds {} bytes, but the header's counts (NumberOfPoints, "
                                  "NumberOfPolys, NumberOfComponents, ...) need {}", array.name,
                                  held.back().bytes, array.bytes));
    }
  }
  CheckOffsets(bytes, layout, held, file);
}

}  // namespace crease
