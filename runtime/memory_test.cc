// runtime/memory.h: the huge-page allocator of a one-scan process.
#include "runtime/memory.h"

#include <gtest/gtest.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

namespace vellum {
namespace {

// The huge-page allocator (set for every later Mat of this test program, which changes no
// other test's result): a large Mat's block is 2 MB aligned, a freed one serves the next Mat of
// its size, small Mats and Mats over memory they do not own are as before.
TEST(HugePages, LargeImagesAreAlignedAndTheirBlocksReused) {
  UseMemoryForOneRun();
  constexpr uintptr_t kTwoMb = uintptr_t{2} << 20;
  const uchar* first = nullptr;
  {
    cv::Mat big(1200, 1600, CV_32F, cv::Scalar(7));  // 7.3 MB.
    EXPECT_EQ(reinterpret_cast<uintptr_t>(big.data) % kTwoMb, 0u);
    EXPECT_EQ(big.at<float>(1199, 1599), 7.0f);
    first = big.data;
  }
  cv::Mat again(1200, 1600, CV_32F);
  EXPECT_EQ(again.data, first) << "a freed block serves the next image of its size";
  cv::Mat other(1200, 1600, CV_32FC3);  // 22 MB: a block of its own.
  EXPECT_NE(other.data, first);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(other.data) % kTwoMb, 0u);
  other.setTo(cv::Scalar(1, 2, 3));
  EXPECT_EQ(other.at<cv::Vec3f>(1199, 1599), cv::Vec3f(1, 2, 3));
  cv::Mat roi = other(cv::Rect(10, 10, 100, 100)).clone();  // Small: OpenCV's own.
  EXPECT_EQ(roi.at<cv::Vec3f>(0, 0), cv::Vec3f(1, 2, 3));
  std::vector<float> owned(1600 * 1200, 5.0f);
  cv::Mat wrapped(1200, 1600, CV_32F, owned.data());
  EXPECT_EQ(wrapped.data, reinterpret_cast<uchar*>(owned.data()));
  cv::Mat copy = wrapped.clone();
  EXPECT_EQ(copy.at<float>(600, 800), 5.0f);
}

// Whether every page of [start, start + bytes) is mapped in this process (mincore fails with
// ENOMEM on a range with any page unmapped).
bool Mapped(const uchar* start, size_t bytes) {
  std::vector<unsigned char> resident((bytes + 4095) / 4096);
  return mincore(const_cast<uchar*>(start), bytes, resident.data()) == 0 || errno != ENOMEM;
}

// Whether no page of [start, start + bytes) is mapped, page by page.
bool NoneMapped(const uchar* start, size_t bytes) {
  for (size_t at = 0; at < bytes; at += 4096) {
    if (Mapped(start + at, 4096)) return false;
  }
  return true;
}

// A kept block serves a smaller image from its head, its tail given back; an image no kept
// block holds gives kept blocks back, so kept and used memory never pass the most ever used.
// The sizes are larger than any other test's images, whose kept blocks may be there too.
TEST(HugePages, KeptBlocksNeverRaiseThePeak) {
  UseMemoryForOneRun();
  constexpr size_t kMb = size_t{1} << 20;
  const uchar* head = nullptr;
  {
    cv::Mat big(100, kMb, CV_8U);  // 100 MB.
    head = big.data;
  }
  ASSERT_TRUE(Mapped(head, 100 * kMb)) << "a freed block is kept";
  {
    cv::Mat smaller(60, kMb, CV_8U);
    EXPECT_EQ(smaller.data, head) << "the kept block serves a smaller image from its head";
    EXPECT_TRUE(NoneMapped(head + 60 * kMb, 40 * kMb)) << "its tail is given back";
  }
  cv::Mat larger(130, kMb, CV_8U);  // No kept block holds it: 130 MB of new pages.
  // The kernel may map the new block over the given-back one's addresses; elsewhere they are
  // unmapped.
  for (size_t at = 0; at < 60 * kMb; at += 2 * kMb) {
    const uchar* page = head + at;
    if (page >= larger.data && page < larger.data + 130 * kMb) continue;
    EXPECT_TRUE(NoneMapped(page, 2 * kMb))
        << "the kept block is given back for the new one, at " << at / kMb << " MB";
  }
  larger.setTo(cv::Scalar(9));
  EXPECT_EQ(larger.at<uchar>(129, kMb - 1), 9);
}

}  // namespace
}  // namespace vellum
