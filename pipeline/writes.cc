#include "pipeline/writes.h"

#include <system_error>

namespace vellum {
namespace {

thread_local FileWrites* t_writes = nullptr;

}  // namespace

FileWrites::~FileWrites() {
  // None left running; whoever needed them waited and heard of a failure (a run that ends in
  // an error of its own may leave them unasked).
  static_cast<void>(Wait());
}

void FileWrites::Add(std::function<Status()> write) {
  std::future<Status> done;
  try {
    done = std::async(std::launch::async, write);
  } catch (const std::system_error&) {
    // No thread to be had (the process's limit): written here, at once.
    std::promise<Status> now;
    now.set_value(write());
    done = now.get_future();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  pending_.push_back(std::move(done));
}

void FileWrites::AddFile(const std::string& path,
                         std::function<Status(const std::string& path)> write) {
  std::function<void(const std::string&)> written;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    written = written_;
  }
  Add([path, write = std::move(write), written = std::move(written)] {
    const Status s = write(path);
    if (s.ok() && written) written(path);
    return s;
  });
}

void FileWrites::AfterEachFile(std::function<void(const std::string& path)> written) {
  std::lock_guard<std::mutex> lock(mutex_);
  written_ = std::move(written);
}

Status FileWrites::Wait() {
  std::vector<std::future<Status>> pending;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending.swap(pending_);
  }
  Status first = Status::Ok();
  for (std::future<Status>& f : pending) {
    const Status s = f.get();
    if (first.ok() && !s.ok()) first = s;
  }
  return first;
}

FileWrites* CurrentFileWrites() { return t_writes; }

WritesDuring::WritesDuring(FileWrites* writes) : before_(t_writes) { t_writes = writes; }

WritesDuring::~WritesDuring() { t_writes = before_; }

}  // namespace vellum
