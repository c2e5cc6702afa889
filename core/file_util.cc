#include "core/file_util.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <vector>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>
#include <fmt/format.h>

#include "core/error.h"

namespace crease {
namespace fs = std::filesystem;

namespace {
// "HOST-PID": a temporary's owner. The host keeps a cleanup on one machine from
// taking the temporaries of a live process on another that shares the folder.
std::string OwnerTag() {
  char host[256] = {0};
  if (::gethostname(host, sizeof(host) - 1) != 0 || host[0] == 0) std::snprintf(host, sizeof(host), "host");
  return fmt::format("{}-{}", host, ::getpid());
}

fs::path TempPathFor(const fs::path& path) {
  // Keep the extension last so extension-sniffing writers (OIIO, VTK) still work.
  return path.parent_path() /
         fmt::format(".{}.tmp-{}{}", path.stem().string(), OwnerTag(), path.extension().string());
}
void EnsureParent(const fs::path& path) {
  if (path.has_parent_path() && !path.parent_path().empty()) {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
    if (ec) {
      throw Error(fmt::format("{}: cannot create folder {}: {}", path.string(),
                              path.parent_path().string(), ec.message()));
    }
  }
}
void Commit(const fs::path& tmp, const fs::path& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw Error(fmt::format("{}: cannot move the finished file into place: {}", path.string(),
                            ec.message()));
  }
}
}  // namespace

void WriteFileAtomic(const fs::path& path, const std::function<void(std::ostream&)>& write) {
  EnsureParent(path);
  const fs::path tmp = TempPathFor(path);
  try {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(fmt::format("{}: cannot open for writing", path.string()));
    write(out);
    out.flush();
    if (!out) throw Error(fmt::format("{}: write failed (disk full?)", path.string()));
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  Commit(tmp, path);
}

void WriteFileAtomicVia(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  EnsureParent(path);
  const fs::path tmp = TempPathFor(path);
  try {
    write(tmp);
    if (!fs::exists(tmp)) throw Error(fmt::format("{}: the writer produced no file", path.string()));
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  Commit(tmp, path);
}

void WriteFilesAtomic(const std::vector<PendingFile>& files) {
  std::vector<fs::path> tmps;
  std::error_code ec;
  try {
    for (const PendingFile& f : files) {
      EnsureParent(f.path);
      tmps.push_back(TempPathFor(f.path));
      f.write(tmps.back());
      if (!fs::exists(tmps.back())) throw Error(fmt::format("{}: the writer produced no file", f.path.string()));
    }
  } catch (...) {
    for (const fs::path& t : tmps) fs::remove(t, ec);
    throw;
  }
  for (size_t i = 0; i < files.size(); ++i) Commit(tmps[i], files[i].path);
}

void RequireReadableFile(const fs::path& path) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);  // follows symbolic links
  if (ec && ec != std::errc::no_such_file_or_directory) {
    throw Error(fmt::format("{}: cannot read: {}", path.string(), ec.message()));
  }
  if (!fs::exists(status)) throw Error(fmt::format("{}: file does not exist", path.string()));
  if (fs::is_directory(status)) {
    throw Error(fmt::format("{}: is a folder, expected a file", path.string()));
  }
  // A device (/dev/zero) never ends and a FIFO can block forever (issue 19).
  if (!fs::is_regular_file(status)) {
    throw Error(fmt::format("{}: is not a regular file (a device, FIFO or socket); crease reads only "
                            "regular files", path.string()));
  }
}

std::string ReadFileToString(const fs::path& path) {
  RequireReadableFile(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(fmt::format("{}: cannot open file", path.string()));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string ReadFileTail(const fs::path& path, size_t max_chars) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  std::stringstream ss;
  ss << in.rdbuf();
  std::string s = ss.str();
  if (s.size() > max_chars) s = "…" + s.substr(s.size() - max_chars);
  return s;
}

std::string LowerExtension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void WriteFolderAtomic(const fs::path& out, bool overwrite, const std::function<void(const fs::path&)>& fill) {
  std::error_code ec;
  if (fs::exists(out, ec) && !overwrite) {
    throw Error(fmt::format("{}: already exists (choose another --out, or pass --overwrite)", out.string()));
  }
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  fs::create_directories(parent, ec);
  RemoveStaleTemporaries(out);
  const fs::path tmp = parent / fmt::format(".{}.tmp-{}", out.filename().string(), OwnerTag());
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  if (ec) throw Error(fmt::format("{}: cannot create folder: {}", tmp.string(), ec.message()));
  try {
    fill(tmp);
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  if (fs::exists(out)) fs::remove_all(out);
  fs::rename(tmp, out, ec);
  if (ec) throw Error(fmt::format("{}: cannot move the finished folder into place: {}", out.string(), ec.message()));
}

int RemoveStaleTemporaries(const fs::path& out) {
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  const std::string own = OwnerTag();
  const std::string prefix = fmt::format(".{}.tmp-{}", out.filename().string(), own.substr(0, own.rfind('-') + 1));
  std::error_code ec;
  std::vector<fs::path> stale;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string pid = name.substr(prefix.size());
    if (pid.empty() || pid.size() > 9 || !std::all_of(pid.begin(), pid.end(), [](unsigned char c) { return std::isdigit(c) != 0; })) continue;
    // kill(pid, 0) fails with ESRCH only when no such process exists.
    if (::kill(static_cast<pid_t>(std::stol(pid)), 0) != 0 && errno == ESRCH) stale.push_back(it->path());
  }
  for (const fs::path& p : stale) fs::remove_all(p, ec);
  return static_cast<int>(stale.size());
}

}  // namespace crease
