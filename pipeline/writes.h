// The report's pictures, written on threads of their own while the steps go on: at 1600 x 1200
// each PNG takes 10 to 70 ms, a third of the steps' time after the decode. A run's writes
// belong to its ScanWork; whoever needs the files on disk (a daemon before it hands its product
// on, `vellum process` before its reports) waits for them with Wait, which also gives the first
// that failed. They are never left running: the last owner's destruction waits for them.
#pragma once

#include <functional>
#include <future>
#include <mutex>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

class FileWrites {
 public:
  FileWrites() = default;
  FileWrites(const FileWrites&) = delete;
  FileWrites& operator=(const FileWrites&) = delete;
  ~FileWrites();

  // Runs `write` on a thread of its own (at once, here, when no thread can be had).
  void Add(std::function<Status()> write);
  // The same for a file: `write(path)`, then, when it wrote it, the hook of AfterEachFile.
  void AddFile(const std::string& path, std::function<Status(const std::string& path)> write);
  // What to do with each file AddFile writes once it is written (on its thread): a daemon
  // records its SHA-256 for the scan's manifest (HashRecord).
  void AfterEachFile(std::function<void(const std::string& path)> written);
  // Waits for every write added so far; the first error of them, else ok.
  Status Wait();

 private:
  std::mutex mutex_;
  std::vector<std::future<Status>> pending_;
  std::function<void(const std::string& path)> written_;
};

// The writes of the steps run on this thread (set by the pipeline while it runs a step: a
// stage called on its own writes its pictures itself, at once); null when none.
FileWrites* CurrentFileWrites();

// Sets this thread's current writes for its lifetime (the pipeline, around each step).
class WritesDuring {
 public:
  explicit WritesDuring(FileWrites* writes);
  ~WritesDuring();
  WritesDuring(const WritesDuring&) = delete;
  WritesDuring& operator=(const WritesDuring&) = delete;

 private:
  FileWrites* before_;
};

}  // namespace vellum
