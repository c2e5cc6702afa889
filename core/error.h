// crease::Error — the one exception type of crease. Messages name the file,
// the field and what was expected, e.g.
//   "mesh.ply: vertex 17 has a NaN coordinate".
#pragma once

#include <stdexcept>
#include <string>
#include <utility>

namespace crease {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// Throws Error(message) when `condition` is false. Unlike assert, this stays in
// Release builds; use it for everything input-dependent.
inline void Require(bool condition, const std::string& message) {
  if (!condition) throw Error(message);
}

}  // namespace crease
