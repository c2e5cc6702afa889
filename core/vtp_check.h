// Size checks of a VTK XML PolyData (.vtp) file before VTK reads it (issue 19).
// VTK allocates what the file's XML header (NumberOfPoints, NumberOfComponents, …)
// and its appended-data block headers claim, and crashes (SIGSEGV, SIGFPE) or asks
// for tens of gigabytes when they lie. These checks hold every claimed size against
// the bytes the file holds for it. Kept free of VTK so that tests need no VTK.
#pragma once

#include <string>

namespace crease {

// Checks the sizes in `bytes`, the whole content of the file `file`. Throws Error
// "<file>: not a readable VTK XML PolyData file: <what>" naming the attribute or
// array that lies. Structure it does not understand is left to VTK's own errors.
void CheckVtpSizes(const std::string& bytes, const std::string& file);

}  // namespace crease
