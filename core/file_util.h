// File helpers. Every output of crease is written atomically: to a temporary
// name in the destination folder, then renamed over the destination, so a crash
// or an error never leaves a half-written file behind.
#pragma once

#include <filesystem>
#include <functional>
#include <vector>
#include <ostream>
#include <string>

namespace crease {

// Calls `write(stream)` on a binary stream opened on "<path>.tmp-<pid>", then
// renames it to `path`. Creates missing parent folders. If `write` throws or the
// stream fails, the temporary is removed, `path` is left untouched and an Error
// naming `path` is thrown (the original message is kept).
void WriteFileAtomic(const std::filesystem::path& path,
                     const std::function<void(std::ostream&)>& write);

// Same for writers that need a file name (third-party libraries): `write` gets a
// temporary path with the same extension as `path`, writes it, and on success the
// file is renamed to `path`.
void WriteFileAtomicVia(const std::filesystem::path& path,
                        const std::function<void(const std::filesystem::path& tmp)>& write);

// Reads a whole file; throws Error "<path>: cannot open file" when missing.
std::string ReadFileToString(const std::filesystem::path& path);

// Throws Error "<path>: file does not exist" / "is a folder" / "is not a regular
// file" (devices, FIFOs and sockets are refused: they may never end or block).
void RequireReadableFile(const std::filesystem::path& path);

// The last `max_chars` bytes of a file, prefixed with "…" when cut; "" when it cannot
// be read (for log tails in error reports).
std::string ReadFileTail(const std::filesystem::path& path, size_t max_chars);

// Lower-case extension including the dot (".ply"), "" when none.
std::string LowerExtension(const std::filesystem::path& path);

// Writes a folder: `fill(tmp)` fills a temporary folder next to `out`, which is
// then renamed to `out`. An existing `out` is an Error unless `overwrite` (then it
// is replaced only once `fill` succeeded). If `fill` throws, the temporary folder
// is removed and `out` is left as it was.
// Several files that belong together (a report and its table): all are written to
// temporaries first, then renamed into place; if any write fails, the temporaries
// are removed and no file of the group is touched, so no run leaves a part of its
// output beside an older part. `write(tmp)` must create the file `tmp` (which keeps
// the extension of `path`).
struct PendingFile {
  std::filesystem::path path;
  std::function<void(const std::filesystem::path& tmp)> write;
};
void WriteFilesAtomic(const std::vector<PendingFile>& files);

// The temporary folder is ".NAME.tmp-HOST-PID"; leftovers of killed processes are
// removed first (RemoveStaleTemporaries).
void WriteFolderAtomic(const std::filesystem::path& out, bool overwrite,
                       const std::function<void(const std::filesystem::path&)>& fill);

// Removes the temporary folders ".NAME.tmp-HOST-PID" of `out` (NAME its file name)
// that a crease process on this host left when it was killed: those whose PID is no
// longer running. A live writer's, and another host's, are kept. Returns how many.
int RemoveStaleTemporaries(const std::filesystem::path& out);

}  // namespace crease
