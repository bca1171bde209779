#include "folder_lock.hpp"

#include "liveness.hpp"

#include "job_error.hpp"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <string>
#include <sys/file.h>
#include <unistd.h>

namespace demcal::jobs {

FolderLock::FolderLock(const std::string& dir, const std::string& flag) {
  const std::string path = (std::filesystem::path(dir) / ".demcal-lock").string();
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw JobError(flag, "cannot open the folder's lock file " + path + ": " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    if (err == ENOLCK || err == EOPNOTSUPP) {  // a file system without locks (some NFS mounts)
      unsupported_ = std::strerror(err);
      return;
    }
    char buf[300] = {};
    const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
    std::string holder = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
    holder = holder.substr(0, holder.find('\n'));
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK)
      throw JobError(flag, "another demcal (" + (holder.empty() ? std::string("pid unknown") : holder) +
                               ") is writing into " + dir + ": wait for it to finish, or give this one another folder");
    throw JobError(flag, "cannot lock " + path + ": " + std::strerror(err));
  }
  // Who holds it, for the message above: written before the old text is cut, so a
  // reader never finds the file empty.
  const std::string who = "pid " + std::to_string(::getpid()) + " on " + hostname() + "\n";
  if (::pwrite(fd_, who.data(), who.size(), 0) != static_cast<ssize_t>(who.size()) ||
      ::ftruncate(fd_, static_cast<off_t>(who.size())) != 0) {
    // Unwritten, a second study is still refused; its message then says "pid unknown".
  }
}

FolderLock::~FolderLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

}  // namespace demcal::jobs
