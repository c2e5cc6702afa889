#include "core/vtk_io.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

#include <cmath>
#include <fstream>
#include <functional>
#include <string>
#include <utility>
#include <vector>
#include <fmt/format.h>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/mesh_primitives.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;

namespace fs = std::filesystem;





TriMesh TestSphere() {
  TriMesh m = MakeUVSphere(10.0 / 3.0, 5, 7);
  m.V.array() += 1e-13;
  m.UV.array() *= 1.0 / 7.0;
  return m;
}

std::vector<VertexField> TestFields(const TriMesh& m) {
  VertexField error{"error_mm", Eigen::MatrixXd(m.num_vertices(), 1)};
  VertexField offset{"offset", Eigen::MatrixXd(m.num_vertices(), 3)};
  VertexField weights{"weights", Eigen::MatrixXd(m.num_vertices(), 2)};
  for (int i = 0; i < m.num_vertices(); ++i) {
    error.values(i, 0) = 0.1 * i / 3.0;
    offset.values.row(i) = m.V.row(i) * (1.0 / 3.0);
    weights.values.row(i) << i % 2, 1.0 / (i + 1);
  }
  return {error, offset, weights};
}

TEST(Vtp, BinaryRoundTripWithFieldsIsExact) {
  const fs::path file = TestDir() / "sphere.vtp";
  const TriMesh m = TestSphere();
  const std::vector<VertexField> fields = TestFields(m);
  WriteVtp(file, m, fields);
  std::vector<VertexField> read_fields;
  const TriMesh r = ReadVtp(file, &read_fields);
  EXPECT_TRUE(r.V == m.V);
  EXPECT_TRUE(r.F == m.F);
  EXPECT_TRUE(r.UV == m.UV);
  EXPECT_TRUE(r.N == m.N);
  ASSERT_EQ(read_fields.size(), fields.size());
  for (size_t k = 0; k < fields.size(); ++k) {
    EXPECT_EQ(read_fields[k].name, fields[k].name);
    ASSERT_EQ(read_fields[k].values.rows(), fields[k].values.rows());
    ASSERT_EQ(read_fields[k].values.cols(), fields[k].values.cols());
    EXPECT_TRUE(read_fields[k].values == fields[k].values) << fields[k].name;
  }
  const std::string xml = ReadFileToString(file);
  EXPECT_NE(xml.find("TCoords=\"UV\""), std::string::npos);
  EXPECT_NE(xml.find("Normals=\"Normals\""), std::string::npos);
}

TEST(Vtp, AsciiRoundTripIsClose) {
  const fs::path file = TestDir() / "grid.vtp";
  TriMesh m = MakeGrid(3, 2, 3.0, 2.0);
  m.N.resize(0, 3);
  WriteVtp(file, m, {{"height", m.V.col(0)}}, /*binary=*/false);
  EXPECT_NE(ReadFileToString(file).find("format=\"ascii\""), std::string::npos);
  std::vector<VertexField> fields;
  const TriMesh r = ReadVtp(file, &fields);
  EXPECT_TRUE(r.F == m.F);
  EXPECT_FALSE(r.has_normals());
  EXPECT_LE((r.V - m.V).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LE((r.UV - m.UV).cwiseAbs().maxCoeff(), 1e-9);
  ASSERT_EQ(fields.size(), 1u);
  EXPECT_LE((fields[0].values - m.V.col(0)).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(Vtp, BadFieldsAreRejectedAndLeaveNoFile) {
  const fs::path dir = TestDir();
  const fs::path file = dir / "bad.vtp";
  const TriMesh m = MakeGrid(2, 2, 1.0, 1.0);
  EXPECT_ERROR_HAS(WriteVtp(file, m, {{"error", Eigen::MatrixXd::Zero(4, 1)}}),
                   file.string() + ": vertex field 'error' is 4×1, expected 9 rows");
  EXPECT_ERROR_HAS(WriteVtp(file, m, {{"UV", Eigen::MatrixXd::Zero(9, 2)}}), "'UV' is used twice");
  EXPECT_ERROR_HAS(WriteVtp(file, m, {{"", Eigen::MatrixXd::Zero(9, 1)}}), "empty name");
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(Vtp, MissingAndMalformedFilesAreClearErrors) {
  const fs::path dir = TestDir();
  const fs::path missing = dir / "missing.vtp";
  EXPECT_ERROR_HAS(ReadVtp(missing), missing.string() + ": file does not exist");

  const fs::path garbage = dir / "garbage.vtp";
  WriteText(garbage, "this is not xml at all\n");
  EXPECT_ERROR_HAS(ReadVtp(garbage), garbage.string() + ": not a readable VTK XML PolyData file");

  const fs::path truncated = dir / "truncated.vtp";
  WriteVtp(truncated, TestSphere());
  const std::string bytes = ReadFileToString(truncated);
  WriteText(truncated, bytes.substr(0, bytes.size() / 2));  // cut inside the XML
  EXPECT_ERROR_HAS(ReadVtp(truncated), truncated.string() + ": not a readable VTK XML PolyData file");
  WriteText(truncated, bytes.substr(0, bytes.size() - 400));  // cut inside the appended data
  EXPECT_ERROR_HAS(ReadVtp(truncated), truncated.string() + ": not a readable VTK XML PolyData file");

  const fs::path wrong_type = dir / "wrong_type.vtp";
  WriteText(wrong_type,
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\">\n"
            "<UnstructuredGrid></UnstructuredGrid>\n</VTKFile>\n");
  EXPECT_ERROR_HAS(ReadVtp(wrong_type), wrong_type.string() + ": not a readable VTK XML PolyData file");
  EXPECT_ERROR_HAS(ReadVtp(wrong_type), "Cannot find PolyData element");
}

// Issue 19: a binary VTP whose header or appended block headers lie made VTK crash
// (SIGSEGV, SIGFPE) or ask for tens of gigabytes; each is now a clear error.
TEST(Vtp, LyingSizesAreClearErrors) {
  const fs::path file = TestDir() / "lies.vtp";
  WriteVtp(file, TestSphere());
  const std::string bytes = ReadFileToString(file);
  const size_t appended = bytes.find('_', bytes.find("<AppendedData")) + 1;
  auto replaced = [&](const std::string& from, const std::string& to) {
    std::string b = bytes;
    const size_t at = b.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return b.replace(at, from.size(), to);
  };
  auto with_word = [&](int k, uint32_t value) {  // the first array's block header, UInt32 words
    std::string b = bytes;
    for (int i = 0; i < 4; ++i) b[appended + 4 * k + i] = static_cast<char>(value >> (8 * i) & 0xff);
    return b;
  };
  const std::string points = fmt::format("NumberOfPoints=\"{}\"", TestSphere().num_vertices());
  const std::string polys = fmt::format("NumberOfPolys=\"{}\"", TestSphere().num_faces());
  const std::vector<std::pair<std::string, std::string>> cases = {
      {replaced(points, "NumberOfPoints=\"-1\""), "NumberOfPoints=\"-1\" is not a count"},
      {replaced(points, "NumberOfPoints=\"4000000000\""), "is not a count"},
      {replaced(points, "NumberOfPoints=\"2000000000\""), "holds"},
      {replaced(polys, "NumberOfPolys=\"2000000000\""), "array 'offsets' holds"},
      {replaced("NumberOfComponents=\"3\"", "NumberOfComponents=\"2000000000\""), "holds"},
      {with_word(0, 0), "holds 0 bytes"},
      {with_word(1, 0), "bad compressed block sizes"},
      {with_word(0, 0xFFFFFFFF), "past the end of the file"},
  };
  for (const auto& [content, message] : cases) {
    WriteText(file, content);
    EXPECT_ERROR_HAS(ReadVtp(file), file.string() + ": not a readable VTK XML PolyData file: ");
    EXPECT_ERROR_HAS(ReadVtp(file), message);
  }
  // VTK sizes the connectivity by the last offset (here 4e9 values, 32 GB).
  WriteVtp(file, TestSphere(), {}, /*binary=*/false);
  std::string ascii = ReadFileToString(file);
  const size_t end = ascii.find("</DataArray>", ascii.rfind("Name=\"offsets\""));
  const std::string last = std::to_string(3 * TestSphere().num_faces());
  ascii.replace(ascii.rfind(last, end), last.size(), "4000000000");
  WriteText(file, ascii);
  EXPECT_ERROR_HAS(ReadVtp(file), "Polys offsets end at 4000000000, but the connectivity holds");
}

TEST(Vtp, ReadsPolygonsAndStrips) {
  const fs::path file = TestDir() / "polys.vtp";
  WriteText(file,
            "<?xml version=\"1.0\"?>\n"
            "<VTKFile type=\"PolyData\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
            "<PolyData><Piece NumberOfPoints=\"6\" NumberOfVerts=\"0\" NumberOfLines=\"0\" "
            "NumberOfStrips=\"1\" NumberOfPolys=\"1\">\n"
            "<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">\n"
            "0 0 0 1 0 0 1 1 0 0 1 0 2 0 0 2 1 0\n</DataArray></Points>\n"
            "<Strips><DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">1 4 2 5"
            "</DataArray><DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">4</DataArray>"
            "</Strips>\n"
            "<Polys><DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">0 1 2 3"
            "</DataArray><DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">4</DataArray>"
            "</Polys>\n"
            "</Piece></PolyData></VTKFile>\n");
  const TriMesh m = ReadVtp(file);
  ASSERT_EQ(m.num_faces(), 4);
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(m.F.row(2), Eigen::RowVector3i(1, 4, 2));
  EXPECT_EQ(m.F.row(3), Eigen::RowVector3i(2, 4, 5));  // second strip triangle flipped
}

TEST(Pvd, WritesCollectionWithRelativePaths) {
  const fs::path dir = TestDir();
  const TriMesh m = MakeGrid(2, 2, 1.0, 1.0);
  PvdWriter series(dir / "series" / "tracking.pvd");
  for (int t = 0; t < 3; ++t) {
    const fs::path vtp = dir / "series" / "frames" / ("frame_" + std::to_string(t) + ".vtp");
    WriteVtp(vtp, m);
    series.Add(t / 30.0, vtp);
    series.Write();
  }
  series.Add(0.5, dir / "other" / "a&b.vtp");
  series.Write();
  EXPECT_EQ(series.num_steps(), 4);
  const std::string xml = ReadFileToString(dir / "series" / "tracking.pvd");
  EXPECT_EQ(xml.rfind("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\"", 0), 0u) << xml;
  EXPECT_NE(xml.find("<DataSet timestep=\"0\" group=\"\" part=\"0\" file=\"frames/frame_0.vtp\"/>"),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("timestep=\"0.03333333333333333\" group=\"\" part=\"0\" file=\"frames/frame_1.vtp\""),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("file=\"../other/a&amp;b.vtp\""), std::string::npos) << xml;
  EXPECT_NE(xml.find("</Collection>\n</VTKFile>\n"), std::string::npos);
  // The stored paths resolve from the pvd's folder.
  EXPECT_NO_THROW(ReadVtp(dir / "series" / "frames/frame_2.vtp"));
  EXPECT_THROW(series.Add(std::nan(""), dir / "x.vtp"), Error);
}

TEST(AnyMesh, DispatchesOnExtension) {
  const fs::path dir = TestDir();
  const TriMesh m = TestSphere();
  for (const char* name : {"a.vtp", "b.ply", "c.VTP"}) {
    WriteAnyMesh(dir / name, m);
    const TriMesh r = ReadAnyMesh(dir / name);
    EXPECT_TRUE(r.V == m.V) << name;
    EXPECT_TRUE(r.F == m.F) << name;
  }
  const fs::path off = dir / "d.off";
  EXPECT_ERROR_HAS(ReadAnyMesh(off), off.string() + ": unsupported mesh file extension '.off' (supported: .ply, .obj, .vtp)");
  EXPECT_ERROR_HAS(WriteAnyMesh(off, m), "supported: .ply, .obj, .vtp");
}

}  // namespace
}  // namespace crease
