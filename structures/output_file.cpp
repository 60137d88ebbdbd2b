#include "structures/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "structures/scene.h"  // InputError

namespace tb {
namespace {

namespace fs = std::filesystem;

// What an existing path is, for a message: "a directory", "a character device", ...
std::string file_kind(const fs::file_status& st) {
  switch (st.type()) {
    case fs::file_type::directory: return "a directory";
    case fs::file_type::character: return "a character device";
    case fs::file_type::block: return "a block device";
    case fs::file_type::fifo: return "a FIFO";
    case fs::file_type::socket: return "a socket";
    default: return "not a regular file";
  }
}

// The process' file-creation mask without changing it: Linux reports it in /proc/self/status
// ("Umask:", since 4.7). Setting and restoring it with umask() would be the fallback, but that
// is a moment in which a file another thread creates gets mode 0666/0777.
mode_t process_umask() {
  if (std::FILE* f = std::fopen("/proc/self/status", "re")) {
    char line[256];
    unsigned mask = 0;
    bool found = false;
    while (!found && std::fgets(line, sizeof line, f)) found = std::sscanf(line, "Umask: %o", &mask) == 1;
    std::fclose(f);
    if (found) return mode_t(mask);
  }
  const mode_t mask = ::umask(0);
  ::umask(mask);
  return mask;
}

}  // namespace

std::string output_target(const std::string& path) {
  fs::path p = path;
  for (int hops = 0;; ++hops) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) return p.string();
    if (hops == 40) throw InputError("'" + path + "': too many levels of symbolic links");
    const fs::path to = fs::read_symlink(p, ec);
    if (ec) throw InputError("'" + path + "': cannot read the symbolic link (" + ec.message() + ")");
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
}

void check_output_file(const std::string& path) {
  if (path.empty()) throw InputError("empty file name");
  const fs::path target = output_target(path);
  const std::string shown =
      "'" + path + "'" + (target.string() == path ? "" : " (a link to '" + target.string() + "')");
  std::error_code ec;
  const fs::file_status st = fs::status(target, ec);
  if (fs::is_directory(st)) throw InputError(shown + " is a directory, not a file");
  // Writing replaces the file (temporary + rename): a device, FIFO or socket would be replaced by
  // a regular file, and writing into one instead fails, if at all, only after the whole run.
  if (fs::exists(st) && !fs::is_regular_file(st))
    throw InputError(shown + " is " + file_kind(st) + ", not a regular file: refusing to write over it");
  const fs::path parent = target.parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec))
    throw InputError("directory '" + parent.string() + "' of " + shown + " does not exist");
}

// Written to a temporary file beside the target (the file a symlink points to: the link stays, as
// when `run` appends through it), fsync'd, then renamed over it: a reader (or a kill) sees the old
// file or the new one, never half of either. Anything but a regular file is refused, not replaced.
void write_file_durably(const std::string& file, std::string_view text) {
  check_output_file(file);
  const std::string path = output_target(file);
  // A fresh name (mkostemp creates it exclusively): a fixed "<path>.tmp" would truncate a file of
  // that name, e.g. the command's own input.
  std::string tmp = path + ".tmp.XXXXXX";
  const int fd = ::mkostemp(tmp.data(), O_CLOEXEC);
  if (fd < 0) throw InputError(path + ": cannot open for writing (" + std::strerror(errno) + ")");
  // mkostemp makes it 0600; the file gets what open(0644) gives.
  bool ok = ::fchmod(fd, 0644 & ~process_umask()) == 0;
  for (size_t off = 0; ok && off < text.size();) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    ok = n > 0;
    off += ok ? size_t(n) : 0;
  }
  ok = ok && ::fsync(fd) == 0;
  const int err = errno;
  ok = ::close(fd) == 0 && ok;
  if (!ok || std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw InputError(path + ": write failed (" + std::strerror(ok ? errno : err) + ")");
  }
}

}  // namespace tb
