// Output files: one rule for every file the suite writes (CSVs and sidecars, ray and hit files,
// images, caches), checked while parsing (apps) and again when writing. At the bottom layer so
// that workloads/ (ray files) and harness/ (tables, images) write the same way.
#pragma once
#include <string>
#include <string_view>

namespace tb {

// A symlink is written through: the file it points to is the output.
std::string output_target(const std::string& path);  // `path`, or the end of its symlink chain
// InputError unless `path` can be written as a file: not empty, its directory exists, and it is
// absent or a regular file (a directory, device, FIFO or socket is refused, never replaced).
void check_output_file(const std::string& path);
// Writes `bytes` to a temporary file beside the target, fsyncs it and renames it over the target:
// a reader (or a kill, or a full disk) sees the old file or the new one, never half of either.
void write_file_durably(const std::string& path, std::string_view bytes);

}  // namespace tb
