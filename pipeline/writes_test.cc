#include "pipeline/writes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace vellum {
namespace {

// A write goes on beside the caller (Add does not wait for it: this one needs the caller to
// let it finish), Wait waits for all and gives the first failure in the order they were added.
TEST(FileWrites, WritesGoOnBesideTheCallerAndWaitGivesTheFirstFailure) {
  FileWrites writes;
  std::promise<void> go;
  std::shared_future<void> started = go.get_future().share();
  std::atomic<int> done{0};
  writes.Add([started, &done] {
    started.wait();
    ++done;
    return Status::Ok();
  });
  writes.Add([&done] {
    ++done;
    return Status::Error("report/outline.png: cannot write");
  });
  writes.Add([&done] {
    ++done;
    return Status::Error("report/texture.png: cannot write");
  });
  go.set_value();  // Reached only because Add returned before the first write ended.
  const Status s = writes.Wait();
  EXPECT_EQ(done.load(), 3);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "report/outline.png: cannot write");
  EXPECT_TRUE(writes.Wait().ok()) << "each write is reported once";
}

// Never left running: the writes' owner waits for them as it goes.
TEST(FileWrites, TheOwnerWaitsForItsWritesAsItGoes) {
  std::atomic<bool> written{false};
  std::promise<void> go;
  std::thread release;
  {
    FileWrites writes;
    std::shared_future<void> started = go.get_future().share();
    writes.Add([started, &written] {
      started.wait();
      written = true;
      return Status::Ok();
    });
    release = std::thread([&go] { go.set_value(); });
  }
  EXPECT_TRUE(written.load());
  release.join();
}

// A file written through AddFile is handed to the hook once it is written, on the write's
// thread, before Wait returns; one that failed is not.
TEST(FileWrites, EachFileWrittenIsHandedToTheHookBeforeWaitReturns) {
  FileWrites writes;
  std::mutex mutex;
  std::vector<std::string> heard;
  writes.AfterEachFile([&](const std::string& path) {
    std::lock_guard<std::mutex> lock(mutex);
    heard.push_back(path);
  });
  for (const char* name : {"points.ply", "depth.png", "report/valid.png"}) {
    writes.AddFile(name, [](const std::string&) { return Status::Ok(); });
  }
  writes.AddFile("report/depth.png",
                 [](const std::string& path) { return Status::Error(path + ": cannot write"); });
  EXPECT_FALSE(writes.Wait().ok());
  std::sort(heard.begin(), heard.end());
  EXPECT_EQ(heard, (std::vector<std::string>{"depth.png", "points.ply", "report/valid.png"}));
}

// The pipeline sets the writes of the steps it runs for their duration, and puts back what was
// there (none, for a stage called on its own, which then writes at once).
TEST(FileWrites, TheStepsWritesAreSetForTheirDurationOnly) {
  EXPECT_EQ(CurrentFileWrites(), nullptr);
  FileWrites outer, inner;
  {
    const WritesDuring a(&outer);
    EXPECT_EQ(CurrentFileWrites(), &outer);
    {
      const WritesDuring b(&inner);
      EXPECT_EQ(CurrentFileWrites(), &inner);
    }
    EXPECT_EQ(CurrentFileWrites(), &outer);
    std::thread([] { EXPECT_EQ(CurrentFileWrites(), nullptr) << "another thread's own"; }).join();
  }
  EXPECT_EQ(CurrentFileWrites(), nullptr);
}

}  // namespace
}  // namespace vellum
