#include "core/vtk_io.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string_view>
#include <fmt/format.h>
#include <vtkCallbackCommand.h>
#include <vtkCellArray.h>
#include <vtkCellArrayIterator.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkDoubleArray.h>
#include <vtkErrorCode.h>
#include <vtkExecutive.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLPolyDataWriter.h>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/vtp_check.h"

namespace crease {
namespace fs = std::filesystem;

namespace {

// Collects the error and warning events of one VTK reader or writer (and of its
// executive and XML parser) so that VTK prints nothing and the first error can be
// put into the crease::Error message. One handler instead of a check after each call.
class VtkMessages {
 public:
  // Observes `algorithm` and its executive.
  void Watch(vtkAlgorithm* algorithm) {
    callback_->SetCallback(&VtkMessages::OnEvent);
    callback_->SetClientData(this);
    algorithm->AddObserver(vtkCommand::ErrorEvent, callback_);
    algorithm->AddObserver(vtkCommand::WarningEvent, callback_);
    if (vtkExecutive* executive = algorithm->GetExecutive()) {
      executive->AddObserver(vtkCommand::ErrorEvent, callback_);
      executive->AddObserver(vtkCommand::WarningEvent, callback_);
    }
  }
  vtkCommand* callback() { return callback_; }

  bool has_error() const { return !error_.empty(); }
  // The first error, or else the first warning, or a generic text.
  std::string Describe() const {
    if (!error_.empty()) return error_;
    if (!warning_.empty()) return warning_;
    return "unknown VTK error";
  }

 private:
  static void OnEvent(vtkObject*, unsigned long event, void* client_data, void* call_data) {
    auto* self = static_cast<VtkMessages*>(client_data);
    std::string& slot = event == vtkCommand::ErrorEvent ? self->error_ : self->warning_;
    if (!slot.empty()) return;
    const char* text = static_cast<const char*>(call_data);
    slot = Clean(text != nullptr && *text != '\0' ? text : "unspecified VTK error");
  }

  // VTK messages look like "ERROR: In <source>, line <n>\n<Class> (0x...): <text>\n\n";
  // keep <text>.
  static std::string Clean(std::string_view text) {
    if (text.rfind("ERROR: In ", 0) == 0 || text.rfind("Warning: In ", 0) == 0) {
      const size_t newline = text.find('\n');
      if (newline != std::string_view::npos) text.remove_prefix(newline + 1);
    }
    const size_t object = text.find("): ");
    if (object != std::string_view::npos && object < 80 && text.find(" (0x") < object) {
      text.remove_prefix(object + 3);
    }
    while (!text.empty() && (text.back() == '\n' || text.back() == ' ' || text.back() == '\r')) {
      text.remove_suffix(1);
    }
    std::string out(text);
    std::replace(out.begin(), out.end(), '\n', ' ');
    return out;
  }

  vtkNew<vtkCallbackCommand> callback_;
  std::string error_;
  std::string warning_;
};

vtkSmartPointer<vtkDoubleArray> MakeArray(const char* name, int components, Eigen::Index rows) {
  auto array = vtkSmartPointer<vtkDoubleArray>::New();
  array->SetName(name);
  array->SetNumberOfComponents(components);
  array->SetNumberOfTuples(rows);
  return array;
}

// Copies a row-major #rows×k matrix into an array.
template <class Matrix>
vtkSmartPointer<vtkDoubleArray> ToArray(const char* name, const Matrix& m) {
  auto array = MakeArray(name, static_cast<int>(m.cols()), m.rows());
  double* out = array->GetPointer(0);
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index k = 0; k < m.cols(); ++k) *out++ = m(i, k);
  }
  return array;
}

Eigen::MatrixXd FromArray(vtkDataArray* array) {
  const Eigen::Index rows = array->GetNumberOfTuples();
  const int cols = array->GetNumberOfComponents();
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < rows; ++i) {
    for (int k = 0; k < cols; ++k) m(i, k) = array->GetComponent(i, k);
  }
  return m;
}

std::string XmlEscape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

}  // namespace

void WriteVtp(const fs::path& path, const TriMesh& mesh, const std::vector<VertexField>& fields,
              bool binary) {
  const std::string file = path.string();
  ValidateMesh(mesh, file, {.non_empty = false});
  std::set<std::string> names = {"UV", "Normals"};
  for (const VertexField& field : fields) {
    Require(!field.name.empty(), fmt::format("{}: a vertex field has an empty name", file));
    Require(names.insert(field.name).second,
            fmt::format("{}: vertex field name '{}' is used twice (\"UV\" and \"Normals\" are reserved "
                        "for the mesh's UVs and normals)", file, field.name));
    Require(field.values.rows() == mesh.num_vertices() && field.values.cols() >= 1,
            fmt::format("{}: vertex field '{}' is {}×{}, expected {} rows (one per vertex) and at least "
                        "one column", file, field.name, field.values.rows(), field.values.cols(),
                        mesh.num_vertices()));
  }

  vtkNew<vtkPolyData> poly;
  vtkNew<vtkPoints> points;
  points->SetData(ToArray("Points", mesh.V));
  poly->SetPoints(points);
  vtkNew<vtkCellArray> triangles;
  triangles->AllocateExact(mesh.num_faces(), 3 * static_cast<vtkIdType>(mesh.num_faces()));
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const vtkIdType ids[3] = {mesh.F(f, 0), mesh.F(f, 1), mesh.F(f, 2)};
    triangles->InsertNextCell(3, ids);
  }
  poly->SetPolys(triangles);
  vtkPointData* point_data = poly->GetPointData();
  if (mesh.has_uv()) point_data->SetTCoords(ToArray("UV", mesh.UV));
  if (mesh.has_normals()) point_data->SetNormals(ToArray("Normals", mesh.N));
  for (const VertexField& field : fields) point_data->AddArray(ToArray(field.name.c_str(), field.values));

  WriteFileAtomicVia(path, [&](const fs::path& tmp) {
    vtkNew<vtkXMLPolyDataWriter> writer;
    VtkMessages messages;
    messages.Watch(writer);
    writer->SetFileName(tmp.string().c_str());
    writer->SetInputData(poly);
    if (binary) {
      writer->SetDataModeToAppended();
      writer->EncodeAppendedDataOff();
      writer->SetCompressorTypeToLZ4();
    } else {
      writer->SetDataModeToAscii();
    }
    if (writer->Write() != 1 || messages.has_error() || writer->GetErrorCode() != vtkErrorCode::NoError) {
      throw Error(fmt::format("{}: VTK could not write the file: {}", file, messages.Describe()));
    }
  });
}

TriMesh ReadVtp(const fs::path& path, std::vector<VertexField>* fields) {
  const std::string file = path.string();
  const std::string bytes = ReadFileToString(path);
  CheckVtpSizes(bytes, file);  // VTK trusts the sizes in the file (issue 19)
  vtkNew<vtkXMLPolyDataReader> reader;
  VtkMessages messages;
  messages.Watch(reader);
  reader->SetReaderErrorObserver(messages.callback());
  reader->SetParserErrorObserver(messages.callback());
  reader->ReadFromInputStringOn();  // the bytes just checked, not the file again
  reader->SetInputString(bytes);
  reader->Update();
  vtkPolyData* poly = reader->GetOutput();
  if (messages.has_error() || reader->GetErrorCode() != vtkErrorCode::NoError || poly == nullptr) {
    throw Error(fmt::format("{}: not a readable VTK XML PolyData file: {}", file, messages.Describe()));
  }
  const vtkIdType num_points = poly->GetNumberOfPoints();
  if (num_points == 0 || poly->GetPoints() == nullptr) {
    throw Error(fmt::format("{}: the file holds no points (empty or not a VTK XML PolyData file)", file));
  }

  TriMesh mesh;
  mesh.V.resize(num_points, 3);
  for (vtkIdType i = 0; i < num_points; ++i) {
    double p[3];
    poly->GetPoints()->GetPoint(i, p);
    mesh.V.row(i) << p[0], p[1], p[2];
  }

  std::vector<int> triangles;
  auto add_triangle = [&](vtkIdType a, vtkIdType b, vtkIdType c) {
    for (vtkIdType v : {a, b, c}) {
      if (v < 0 || v >= num_points) {
        throw Error(fmt::format("{}: a cell references point {}, but the file has {} points", file, v,
                                num_points));
      }
    }
    triangles.insert(triangles.end(), {static_cast<int>(a), static_cast<int>(b), static_cast<int>(c)});
  };
  if (vtkCellArray* polys = poly->GetPolys()) {
    auto it = vtk::TakeSmartPointer(polys->NewIterator());
    for (it->GoToFirstCell(); !it->IsDoneWithTraversal(); it->GoToNextCell()) {
      vtkIdType n = 0;
      const vtkIdType* ids = nullptr;
      it->GetCurrentCell(n, ids);
      if (n < 3) {
        throw Error(fmt::format("{}: polygon {} has {} points, needs at least 3", file,
                                it->GetCurrentCellId(), n));
      }
      for (vtkIdType k = 1; k + 1 < n; ++k) add_triangle(ids[0], ids[k], ids[k + 1]);  // fan
    }
  }
  if (vtkCellArray* strips = poly->GetStrips()) {
    auto it = vtk::TakeSmartPointer(strips->NewIterator());
    for (it->GoToFirstCell(); !it->IsDoneWithTraversal(); it->GoToNextCell()) {
      vtkIdType n = 0;
      const vtkIdType* ids = nullptr;
      it->GetCurrentCell(n, ids);
      for (vtkIdType k = 0; k + 2 < n; ++k) {  // every other triangle flips to keep the orientation
        if (k % 2 == 0) {
          add_triangle(ids[k], ids[k + 1], ids[k + 2]);
        } else {
          add_triangle(ids[k + 1], ids[k], ids[k + 2]);
        }
      }
    }
  }
  mesh.F = Eigen::Map<const MatX3i>(triangles.data(), static_cast<Eigen::Index>(triangles.size() / 3), 3);

  vtkPointData* point_data = poly->GetPointData();
  vtkDataArray* uv = point_data->GetTCoords();
  if (uv == nullptr) uv = point_data->GetArray("UV");
  vtkDataArray* normals = point_data->GetNormals();
  if (uv != nullptr && uv->GetNumberOfComponents() >= 2 && uv->GetNumberOfTuples() == num_points) {
    mesh.UV.resize(num_points, 2);
    for (vtkIdType i = 0; i < num_points; ++i) mesh.UV.row(i) << uv->GetComponent(i, 0), uv->GetComponent(i, 1);
  } else {
    uv = nullptr;
  }
  if (normals != nullptr && normals->GetNumberOfComponents() == 3 && normals->GetNumberOfTuples() == num_points) {
    mesh.N = FromArray(normals);
  } else {
    normals = nullptr;
  }
  if (fields != nullptr) {
    fields->clear();
    for (int a = 0; a < point_data->GetNumberOfArrays(); ++a) {
      vtkDataArray* array = point_data->GetArray(a);  // nullptr for non-numeric arrays
      if (array == nullptr || array == uv || array == normals) continue;
      if (array->GetNumberOfTuples() != num_points) {
        throw Error(fmt::format("{}: point array '{}' has {} values for {} points", file,
                                array->GetName() ? array->GetName() : "", array->GetNumberOfTuples(),
                                num_points));
      }
      fields->push_back({array->GetName() ? array->GetName() : fmt::format("array{}", a), FromArray(array)});
    }
  }
  ValidateMesh(mesh, file);
  return mesh;
}

PvdWriter::PvdWriter(const fs::path& pvd_path)
    : path_(pvd_path), folder_(fs::absolute(pvd_path).parent_path().lexically_normal()) {}

void PvdWriter::Add(double time, const fs::path& vtp_file) {
  Require(std::isfinite(time), fmt::format("{}: time step {} is not finite", path_.string(), time));
  const fs::path absolute = fs::absolute(vtp_file).lexically_normal();
  fs::path relative = absolute.lexically_relative(folder_);
  if (relative.empty()) relative = absolute;  // another root: keep it absolute
  steps_.push_back({time, relative.generic_string()});
}

void PvdWriter::Write() const {
  WriteFileAtomic(path_, [&](std::ostream& out) {
    std::string xml =
        "<?xml version=\"1.0\"?>\n"
        "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        "  <Collection>\n";
    for (const Step& step : steps_) {
      xml += fmt::format("    <DataSet timestep=\"{}\" group=\"\" part=\"0\" file=\"{}\"/>\n", step.time,
                         XmlEscape(step.file));
    }
    xml += "  </Collection>\n</VTKFile>\n";
    out.write(xml.data(), static_cast<std::streamsize>(xml.size()));
  });
}

TriMesh ReadAnyMesh(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".vtp") return ReadVtp(path);
  if (ext == ".ply" || ext == ".obj") return ReadMesh(path);
  throw Error(fmt::format("{}: unsupported mesh file extension '{}' (supported: .ply, .obj, .vtp)",
                          path.string(), ext.empty() ? "(none)" : ext));
}

void WriteAnyMesh(const fs::path& path, const TriMesh& mesh) {
  const std::string ext = LowerExtension(path);
  if (ext == ".vtp") return WriteVtp(path, mesh);
  if (ext == ".ply" || ext == ".obj") return WriteMesh(path, mesh);
  throw Error(fmt::format("{}: unsupported mesh file extension '{}' (supported: .ply, .obj, .vtp)",
                          path.string(), ext.empty() ? "(none)" : ext));
}

}  // namespace crease
