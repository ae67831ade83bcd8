#include "io/ply.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "io/file_bytes.h"
#include "io/input_text.h"
#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

// A name from the file's header (an element's) for an error's field: as
// written when it is a short plain word ("vertex", "face"), else quoted by
// InputToken, so a header line cannot put control bytes or a long text into
// an error message.
std::string HeaderName(const std::string& name) {
  const bool plain = !name.empty() && name.size() <= kMaxInputTokenChars &&
                     std::all_of(name.begin(), name.end(), [](char c) {
                       return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
                     });
  return plain ? name : InputToken(name);
}

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool ParsePlyType(const std::string& s, PlyType* t) {
  if (s == "char" || s == "int8")
    *t = PlyType::kInt8;
  else if (s == "uchar" || s == "uint8")
    *t = PlyType::kUint8;
  else if (s == "short" || s == "int16")
    *t = PlyType::kInt16;
  else if (s == "ushort" || s == "uint16")
    *t = PlyType::kUint16;
  else if (s == "int" || s == "int32")
    *t = PlyType::kInt32;
  else if (s == "uint" || s == "uint32")
    *t = PlyType::kUint32;
  else if (s == "float" || s == "float32")
    *t = PlyType::kFloat32;
  else if (s == "double" || s == "float64")
    *t = PlyType::kFloat64;
  else
    return false;
  return true;
}

int TypeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8: return 1;
    case PlyType::kInt16:
    case PlyType::kUint16: return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
  }
  return 0;
}

bool IsIntegral(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  // Smallest number of bytes one entry can take (binary) or characters (ASCII, a digit and a separator each).
  std::uint64_t MinBytes(bool binary) const {
    std::uint64_t n = 0;
    for (const auto& p : properties) n += binary ? TypeSize(p.is_list ? p.count_type : p.type) : 2;
    return n;
  }
};

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

// Reads values from the body of the file, ASCII tokens or binary scalars.
class PlyBody {
 public:
  PlyBody(const std::string& file, const std::string& data, size_t offset, PlyFormat format)
      : file_(file), data_(data), pos_(offset), format_(format) {}

  std::uint64_t Remaining() const { return data_.size() - pos_; }

  double Read(PlyType type, const std::string& field) {
    return format_ == PlyFormat::kAscii ? ReadAscii(type, field) : ReadBinary(type, field);
  }

 private:
  double ReadAscii(PlyType type, const std::string& field) {
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
    if (pos_ >= data_.size()) throw InputError(file_, field, "file is truncated (expected another value)");
    size_t end = pos_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    const char* begin = data_.c_str() + pos_;
    char* stop = nullptr;
    const double v = std::strtod(begin, &stop);
    const size_t start = pos_;
    pos_ = end;
    if (stop != data_.c_str() + end || (IsIntegral(type) && v != std::floor(v)))
      throw InputError(file_, field,
                       InputToken(data_.substr(start, end - start)) + " is not a" +
                           (IsIntegral(type) ? "n integer" : " number"));
    return v;
  }

  template <typename T>
  T Raw() {
    T v;
    std::memcpy(&v, data_.data() + pos_, sizeof(T));
    if (format_ == PlyFormat::kBinaryBigEndian) {
      auto* b = reinterpret_cast<unsigned char*>(&v);
      std::reverse(b, b + sizeof(T));
    }
    pos_ += sizeof(T);
    return v;
  }

  double ReadBinary(PlyType type, const std::string& field) {
    if (static_cast<std::uint64_t>(TypeSize(type)) > Remaining())
      throw InputError(file_, field, "file is truncated at byte " + std::to_string(pos_));
    switch (type) {
      case PlyType::kInt8: return Raw<std::int8_t>();
      case PlyType::kUint8: return Raw<std::uint8_t>();
      case PlyType::kInt16: return Raw<std::int16_t>();
      case PlyType::kUint16: return Raw<std::uint16_t>();
      case PlyType::kInt32: return Raw<std::int32_t>();
      case PlyType::kUint32: return Raw<std::uint32_t>();
      case PlyType::kFloat32: return Raw<float>();
      case PlyType::kFloat64: return Raw<double>();
    }
    return 0;
  }

  const std::string& file_;
  const std::string& data_;
  size_t pos_;
  PlyFormat format_;
};

int PropertyIndex(const PlyElement& e, std::initializer_list<const char*> names) {
  for (size_t i = 0; i < e.properties.size(); ++i)
    for (const char* n : names)
      if (e.properties[i].name == n && !e.properties[i].is_list) return static_cast<int>(i);
  return -1;
}

}  // namespace

TriangleMesh ReadPly(const fs::path& path) {
  const std::string file = path.string();
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(file, "PLY file does not exist");
  const std::string data = ReadFileBytes(path);

  // Header: lines up to "end_header".
  size_t pos = 0;
  int line_number = 0;
  auto next_line = [&](std::string* line) {
    if (pos >= data.size()) return false;
    size_t end = data.find('\n', pos);
    if (end == std::string::npos) end = data.size();
    *line = data.substr(pos, end - pos);
    if (!line->empty() && line->back() == '\r') line->pop_back();
    pos = std::min(end + 1, data.size());
    ++line_number;
    return true;
  };
  std::string line;
  if (!next_line(&line) || line != "ply") throw InputError(file, "line 1", "not a PLY file (no 'ply' magic)");
  PlyFormat format = PlyFormat::kAscii;
  bool have_format = false, have_end = false;
  std::vector<PlyElement> elements;
  while (next_line(&line)) {
    const std::string field = "header line " + std::to_string(line_number);
    std::istringstream in(line);
    std::string keyword;
    in >> keyword;
    if (keyword.empty() || keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") {
      have_end = true;
      break;
    }
    if (keyword == "format") {
      std::string name, version;
      in >> name >> version;
      if (name == "ascii")
        format = PlyFormat::kAscii;
      else if (name == "binary_little_endian")
        format = PlyFormat::kBinaryLittleEndian;
      else if (name == "binary_big_endian")
        format = PlyFormat::kBinaryBigEndian;
      else
        throw InputError(file, field, "unknown format " + InputToken(name));
      have_format = true;
    } else if (keyword == "element") {
      PlyElement e;
      std::string count;
      in >> e.name >> count;
      char* end = nullptr;
      errno = 0;
      e.count = std::strtoull(count.c_str(), &end, 10);
      if (e.name.empty() || count.empty() || count[0] == '-' || *end != '\0' || errno == ERANGE)
        throw InputError(file, field,
                         "malformed element line (name " + InputToken(e.name) + ", count " + InputToken(count) + ")");
      elements.push_back(e);
    } else if (keyword == "property") {
      if (elements.empty()) throw InputError(file, field, "property before any element");
      PlyProperty p;
      std::string type;
      in >> type;
      if (type == "list") {
        std::string count_type, item_type;
        in >> count_type >> item_type >> p.name;
        p.is_list = true;
        if (!ParsePlyType(count_type, &p.count_type) || !ParsePlyType(item_type, &p.type) ||
            !IsIntegral(p.count_type))
          throw InputError(file, field,
                           "malformed list property (count type " + InputToken(count_type) + ", item type " +
                               InputToken(item_type) + ")");
      } else {
        in >> p.name;
        if (!ParsePlyType(type, &p.type))
          throw InputError(file, field, "unknown property type " + InputToken(type));
      }
      if (p.name.empty()) throw InputError(file, field, "property without a name");
      elements.back().properties.push_back(p);
    } else {
      throw InputError(file, field, "unexpected header keyword " + InputToken(keyword));
    }
  }
  if (!have_format) throw InputError(file, "header", "no format line");
  if (!have_end) throw InputError(file, "header", "no end_header (truncated file?)");

  const bool binary = format != PlyFormat::kAscii;
  PlyBody body(file, data, pos, format);
  TriangleMesh mesh;
  bool have_vertices = false;
  for (const PlyElement& e : elements) {
    // Counts must be coverable by the bytes left, so a corrupt header cannot make us allocate.
    // An entry without properties takes no bytes, so no file size bounds its count: refused.
    if (e.properties.empty() && e.count > 0)
      throw InputError(file, "element " + HeaderName(e.name),
                       "has no properties but a count of " + std::to_string(e.count));
    const std::uint64_t min_bytes = e.MinBytes(binary);
    if (min_bytes > 0 && e.count > body.Remaining() / min_bytes)
      throw InputError(file, "element " + HeaderName(e.name),
                       "count " + std::to_string(e.count) + " does not fit in the " +
                           std::to_string(body.Remaining()) + " bytes left (truncated or corrupt file)");
    if (e.name == "vertex") {
      have_vertices = true;
      const int ix = PropertyIndex(e, {"x"}), iy = PropertyIndex(e, {"y"}), iz = PropertyIndex(e, {"z"});
      if (ix < 0 || iy < 0 || iz < 0) throw InputError(file, "element vertex", "needs properties x, y and z");
      const int inx = PropertyIndex(e, {"nx"}), iny = PropertyIndex(e, {"ny"}),
                inz = PropertyIndex(e, {"nz"});
      const int ir = PropertyIndex(e, {"red", "r", "diffuse_red"});
      const int ig = PropertyIndex(e, {"green", "g", "diffuse_green"});
      const int ib = PropertyIndex(e, {"blue", "b", "diffuse_blue"});
      const bool normals = inx >= 0 && iny >= 0 && inz >= 0;
      const bool colors = ir >= 0 && ig >= 0 && ib >= 0;
      mesh.vertices.resize(e.count);
      if (normals) mesh.normals.resize(e.count);
      if (colors) mesh.colors.resize(e.count);
      std::vector<double> values(e.properties.size());
      for (std::uint64_t v = 0; v < e.count; ++v) {
        const std::string field = "vertex " + std::to_string(v);
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const PlyProperty& p = e.properties[k];
          if (!p.is_list) {
            values[k] = body.Read(p.type, field);
          } else {
            const double n = body.Read(p.count_type, field);
            if (n < 0 || n > body.Remaining()) throw InputError(file, field, "bad list length");
            for (std::uint64_t j = 0; j < static_cast<std::uint64_t>(n); ++j) body.Read(p.type, field);
          }
        }
        mesh.vertices[v] = Eigen::Vector3f(values[ix], values[iy], values[iz]);
        if (normals) mesh.normals[v] = Eigen::Vector3f(values[inx], values[iny], values[inz]);
        if (colors) {
          // Colours are uchar in practice; float colours are taken as [0, 1], ushort as [0, 65535].
          auto to8 = [&](int k) {
            double c = values[k];
            const PlyType t = e.properties[k].type;
            if (!IsIntegral(t))
              c *= 255.0;
            else if (t == PlyType::kUint16)
              c /= 257.0;
            return static_cast<std::uint8_t>(std::clamp(std::round(c), 0.0, 255.0));
          };
          mesh.colors[v] = Color3u8(to8(ir), to8(ig), to8(ib));
        }
      }
    } else if (e.name == "face") {
      int list_index = -1;
      for (size_t k = 0; k < e.properties.size(); ++k)
        if (e.properties[k].is_list &&
            (e.properties[k].name == "vertex_indices" || e.properties[k].name == "vertex_index"))
          list_index = static_cast<int>(k);
      if (list_index < 0) throw InputError(file, "element face", "needs a list property vertex_indices");
      if (!IsIntegral(e.properties[list_index].type))
        throw InputError(file, "element face", "vertex indices must be integers");
      mesh.triangles.reserve(e.count);
      std::vector<int> polygon;
      std::uint64_t skipped = 0;
      for (std::uint64_t f = 0; f < e.count; ++f) {
        const std::string field = "face " + std::to_string(f);
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const PlyProperty& p = e.properties[k];
          if (!p.is_list) {
            body.Read(p.type, field);
            continue;
          }
          const double n = body.Read(p.count_type, field);
          if (n < 0 || n > body.Remaining())
            throw InputError(file, field, "bad list length " + std::to_string(n));
          polygon.resize(static_cast<size_t>(n));
          for (int& index : polygon) {
            const double value = body.Read(p.type, field);
            if (value < 0 || value > std::numeric_limits<int>::max())
              throw InputError(file, field, "vertex index " + std::to_string(value) + " out of range");
            index = static_cast<int>(value);
          }
          if (static_cast<int>(k) != list_index) continue;
          if (polygon.size() < 3) {
            ++skipped;
            continue;
          }
          for (size_t j = 1; j + 1 < polygon.size(); ++j)  // fan
            mesh.triangles.emplace_back(polygon[0], polygon[j], polygon[j + 1]);
        }
      }
      if (skipped > 0) spdlog::warn("{}: skipped {} faces with fewer than 3 vertices", file, skipped);
    } else {
      // Unknown element (edges, materials...): read past it.
      const std::string name = HeaderName(e.name);
      for (std::uint64_t i = 0; i < e.count; ++i) {
        const std::string field = name + " " + std::to_string(i);
        for (const PlyProperty& p : e.properties) {
          if (!p.is_list) {
            body.Read(p.type, field);
            continue;
          }
          const double n = body.Read(p.count_type, field);
          if (n < 0 || n > body.Remaining()) throw InputError(file, field, "bad list length");
          for (std::uint64_t j = 0; j < static_cast<std::uint64_t>(n); ++j) body.Read(p.type, field);
        }
      }
    }
  }
  if (!have_vertices) throw InputError(file, "header", "no vertex element");
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    if ((mesh.triangles[t].array() >= static_cast<int>(mesh.vertices.size())).any())
      throw InputError(file, "face " + std::to_string(t),
                       "vertex index beyond the " + std::to_string(mesh.vertices.size()) + " vertices");
  }
  spdlog::debug("{}: {} vertices, {} triangles", file, mesh.vertices.size(), mesh.triangles.size());
  return mesh;
}

void WritePly(const TriangleMesh& mesh, const fs::path& path) {
  const bool normals = mesh.HasNormals();
  const bool colors = mesh.HasColors();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw InputError(path.string(), "cannot open file for writing");
  out << "ply\nformat binary_little_endian 1.0\ncomment written by lfrecon\n";
  out << "element vertex " << mesh.vertices.size() << "\n";
  out << "property float x\nproperty float y\nproperty float z\n";
  if (normals) out << "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (!mesh.triangles.empty())
    out << "element face " << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\n";
  out << "end_header\n";
  // Host order is little-endian on every platform we build for (x86-64, aarch64).
  std::vector<char> buffer;
  const size_t stride = 12 + (normals ? 12 : 0) + (colors ? 3 : 0);
  buffer.resize(stride * mesh.vertices.size());
  char* p = buffer.data();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    std::memcpy(p, mesh.vertices[i].data(), 12);
    p += 12;
    if (normals) {
      std::memcpy(p, mesh.normals[i].data(), 12);
      p += 12;
    }
    if (colors) {
      std::memcpy(p, mesh.colors[i].data(), 3);
      p += 3;
    }
  }
  out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
  buffer.assign(13 * mesh.triangles.size(), 0);
  p = buffer.data();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    *p++ = 3;
    std::memcpy(p, t.data(), 12);
    p += 12;
  }
  out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
  out.close();
  if (!out) throw InputError(path.string(), "write failed");
}

}  // namespace lfrecon
