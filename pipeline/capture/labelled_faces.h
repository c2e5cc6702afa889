// Labelled faces for training and evaluating the landmark regressor of the global
// tracker (paper Sec. 5, the DDE-style tracker of Cao et al. 2014;
// pipeline/capture/shape_regressor.h): images with their 68 iBUG landmarks, read from
// and written to folders, and read from dlib's imglab XML. Real photographs and studio
// renders (eval/tracker_renders.h) take the same form; nothing here needs the studio.
//
// Folder format (read and written): NAME.png (8-bit sRGB) with NAME.pts, the iBUG
// 300-W point format ("version: 1", "n_points: 68", "{", one "x y" per line, "}"),
// pixel centres at integer coordinates (crease's convention; 300-W files count from 1,
// so real 300-W data is off by one pixel).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/types.h"

namespace crease {

struct LabelledFace {
  std::string name;
  cv::Mat image;      // CV_8UC3 sRGB (R, G, B), what a camera file holds
  MatX2d landmarks;   // 68×2 truth pixels (iBUG order)
};

// One iBUG .pts file with 68 points; errors name the file and the point.
MatX2d ReadPts(const std::filesystem::path& path);

// Folder I/O (format in the file comment). Reading sorts by name; errors name the file.
// ReadLabelledFaces also takes a dlib XML file (ReadDlibXmlFaces, default options).
// Writing puts each .pts under a temporary name first and renames it.
void WriteLabelledFaces(const std::filesystem::path& folder, const std::vector<LabelledFace>& faces);
std::vector<LabelledFace> ReadLabelledFaces(const std::filesystem::path& folder);

// dlib's imglab XML: the format of dlib's release of iBUG 300-W
// (labels_ibug_300W_train.xml, …) and of its example faces:
//   <image file='F'> <box top='' left='' width='' height=''> <part name='00' x='' y=''/> … </box> … </image>
// Image paths are relative to the XML's folder. Every box with the 68 parts (names
// 00 … 67, any order) becomes one LabelledFace, named after the image and the box:
// a square crop centred on the box, `crop_scale` times the box's larger side,
// resampled (bilinear; black outside the image) so that the box's larger side is
// `box_px` pixels — real photographs hold faces of any size and several per image,
// the regressor and the detector are run on one face of a known scale. Boxes marked
// ignore='1' or without 68 parts are skipped. Errors name the file and line.
struct DlibXmlOptions {
  double crop_scale = 2.5;  // crop side / the box's larger side, ≥ 1
  int box_px = 100;         // the box's larger side in the crop, pixels, ≥ 16
};
std::vector<LabelledFace> ReadDlibXmlFaces(const std::filesystem::path& xml, const DlibXmlOptions& options = {});

}  // namespace crease
