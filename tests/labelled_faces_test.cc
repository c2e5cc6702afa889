// Labelled-face I/O (pipeline/capture/labelled_faces.h): .pts folders and dlib XML.
// Links crease_capture only: reading photographs needs no studio.
#include "pipeline/capture/labelled_faces.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/test_util.h"
#include "tests/toy_faces.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::MakeToy;
using testing::TestDir;
using testing::Toy;
using testing::ToyFaces;

TEST(LabelledFaces, FolderRoundTrip) {
  const Toy toy = MakeToy(2, 7);
  const std::vector<LabelledFace> faces = ToyFaces(toy, "face");
  const auto dir = TestDir();
  WriteLabelledFaces(dir, faces);
  const std::vector<LabelledFace> back = ReadLabelledFaces(dir);
  ASSERT_EQ(back.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(back[i].name, faces[i].name);
    EXPECT_EQ(cv::norm(back[i].image, faces[i].image, cv::NORM_INF), 0.0);
    EXPECT_LT((back[i].landmarks - faces[i].landmarks).cwiseAbs().maxCoeff(), 1e-4);
  }
  testing::WriteText(dir / "face1.pts", "version: 1\nn_points: 68\n{\n1 2\n}\n");
  EXPECT_NE(ErrorOf([&] { ReadLabelledFaces(dir); }).find("face1.pts: point 2"), std::string::npos);
}

// dlib's imglab XML (its 300-W release and example faces): each labelled box becomes
// a crop of known scale whose pixels and landmarks agree; ignored and incomplete
// boxes are skipped; errors name the file and line.
TEST(LabelledFaces, DlibXmlFacesAreCroppedAroundTheirBoxes) {
  const auto dir = TestDir();
  // A 300×200 image with a bright dot at every part of a face in the box
  // (left 100, top 50, 80×80): a ring of 68 points.
  cv::Mat image(200, 300, CV_8UC3, cv::Scalar::all(0));
  std::string parts;
  MatX2d truth(68, 2);
  for (int k = 0; k < 68; ++k) {
    const double a = 2.0 * std::numbers::pi * k / 68.0;
    const int x = static_cast<int>(std::lround(140 + 30 * std::cos(a))), y = static_cast<int>(std::lround(90 + 30 * std::sin(a)));
    truth.row(k) << x, y;
    image.at<cv::Vec3b>(y, x) = cv::Vec3b(255, 255, 255);
    parts += fmt::format("      <part name='{:02d}' x='{}' y='{}'/>\n", k, x, y);
  }
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  ASSERT_TRUE(cv::imwrite((dir / "photo.png").string(), bgr));
  const std::string xml = "<?xml version='1.0'?>\n<!-- labels -->\n<dataset><images>\n"
                          "  <image file='photo.png'>\n"
                          "    <box top='50' left='100' width='80' height='80'>\n" + parts +
                          "    </box>\n"
                          "    <box top='0' left='0' width='20' height='20' ignore='1'>\n" + parts +
                          "    </box>\n"
                          "    <box top='0' left='200' width='20' height='20'>\n"
                          "      <part name='00' x='205' y='5'/>\n"
                          "    </box>\n"
                          "  </image>\n</images></dataset>\n";
  testing::WriteText(dir / "labels.xml", xml);
  const std::vector<LabelledFace> faces = ReadDlibXmlFaces(dir / "labels.xml", {.crop_scale = 2.0, .box_px = 40});
  ASSERT_EQ(faces.size(), 1u);
  const LabelledFace& f = faces[0];
  EXPECT_EQ(f.name, "photo_0");
  ASSERT_EQ(f.image.cols, 80);
  ASSERT_EQ(f.image.rows, 80);
  // Scale 40 / 80 about the box centre (139.5, 89.5) → the crop centre (39.5, 39.5).
  for (int k = 0; k < 68; ++k) {
    EXPECT_NEAR(f.landmarks(k, 0), 0.5 * (truth(k, 0) - 139.5) + 39.5, 1e-9);
    EXPECT_NEAR(f.landmarks(k, 1), 0.5 * (truth(k, 1) - 89.5) + 39.5, 1e-9);
    // The dot is at the landmark: the crop is brighter there than at the centre.
    const int x = static_cast<int>(std::lround(f.landmarks(k, 0))), y = static_cast<int>(std::lround(f.landmarks(k, 1)));
    EXPECT_GT(f.image.at<cv::Vec3b>(y, x)[0], 20) << k;
  }
  EXPECT_EQ(f.image.at<cv::Vec3b>(40, 40)[0], 0);
  // ReadLabelledFaces takes the XML too (train-tracker --data, eval-landmarks --data).
  EXPECT_EQ(ReadLabelledFaces(dir / "labels.xml").size(), 1u);
  // Errors name the file, the line and the problem.
  testing::WriteText(dir / "bad.xml", "<dataset>\n<image file='photo.png'>\n<box top='x' left='0' width='9' height='9'>\n" +
                                          parts + "</box></image></dataset>\n");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "bad.xml"); }).find("bad.xml:3: <box> top='x' is not a number"),
            std::string::npos);
  testing::WriteText(dir / "missing.xml", "<image file='nowhere.jpg'><box top='0' left='0' width='9' height='9'>" +
                                              parts + "</box></image>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "missing.xml"); }).find("image 'nowhere.jpg' not found"),
            std::string::npos);
  // Issue 19: a box of 1e-300 px scaled the crop to infinite coordinates.
  testing::WriteText(dir / "tiny.xml", "<image file='photo.png'><box top='0' left='0' width='1e-300' height='1e-300'>" +
                                           parts + "</box></image>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "tiny.xml"); }).find("tiny.xml:1: <box> smaller than 1 px"),
            std::string::npos);
  testing::WriteText(dir / "empty.xml", "<dataset><images></images></dataset>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "empty.xml"); }).find("no <box> with the 68 <part>s"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "none.xml"); }).find("none.xml: cannot open"), std::string::npos);
}

TEST(LabelledFaces, PtsErrorsNameTheFileAndTheProblem) {
  const auto dir = TestDir();
  EXPECT_NE(ErrorOf([&] { ReadPts(dir / "absent.pts"); }).find("absent.pts: missing landmark file"), std::string::npos);
  testing::WriteText(dir / "few.pts", "version: 1\nn_points: 5\n{\n1 2\n}\n");
  EXPECT_NE(ErrorOf([&] { ReadPts(dir / "few.pts"); }).find("expected 'n_points: 68' before '{' (got 5)"),
            std::string::npos);
  testing::WriteText(dir / "word.pts", "n_points: many\n{\n");
  EXPECT_NE(ErrorOf([&] { ReadPts(dir / "word.pts"); }).find("'n_points:' is not followed by a number"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadLabelledFaces(dir / "absent"); }).find("not a folder of labelled faces"),
            std::string::npos);
}

}  // namespace
}  // namespace crease
