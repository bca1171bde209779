#include "part_file.hpp"

#include "liveness.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <unistd.h>

namespace demcal::jobs {

PartFile::PartFile(std::string path) : path_(std::move(path)), part_(path_ + ".part") {}
PartFile::PartFile(std::string path, std::string part) : path_(std::move(path)), part_(std::move(part)) {}

PartFile PartFile::private_to_this_process(std::string path) {
  // The pid namespace in the name too: a later run judges the writer gone by its pid
  // (leftover_files), which only a process of the same namespace can.
  std::string part = path + "." + process_host_tag() + "-" + std::to_string(::getpid()) + ".part";
  return PartFile(std::move(path), std::move(part));
}

PartFile::~PartFile() {
  if (!done_) std::remove(part_.c_str());
}

bool folder_takes_a_file(const std::filesystem::path& dir) {
  const std::string probe = (dir / (".probe-" + std::to_string(::getpid()))).string();
  bool ok = false;
  {
    std::ofstream f(probe, std::ios::binary | std::ios::trunc);
    const std::string block(64 * 1024, '\0');
    f << block;
    f.flush();
    ok = static_cast<bool>(f);
    f.close();
    ok = ok && static_cast<bool>(f);
  }
  std::remove(probe.c_str());
  return ok;
}

std::string why_folder_takes_no_file(const std::filesystem::path& dir) {
  std::error_code ec;
  const auto st = std::filesystem::status(dir, ec);
  if (st.type() == std::filesystem::file_type::not_found) return "the folder is gone: make it again and run the job again";
  if (!ec && st.type() != std::filesystem::file_type::directory)
    return "something else than a folder is at its path now: put the folder back and run the job again";
  return "disk full, or the folder not writable: free space (or fix the folder) and run the job again";
}

void PartFile::commit(const std::string& what) {
  // On failure the part stays uncommitted, and the destructor removes it.
  if (std::rename(part_.c_str(), path_.c_str()) != 0)
    throw OutputWriteError("cannot move the " + what + " into place at " + path_ + ": " + std::strerror(errno));
  done_ = true;
}

}  // namespace demcal::jobs
