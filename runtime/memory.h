// How a process holds its large images: the kernel's huge pages for them.
//
// A 1600 x 1200 scan's pipeline touches some 240 MB of fresh buffers. On a 4 kB page each first
// touch faults (60 000 faults), and under a hypervisor each fault is dear: a quarter of
// `vellum process`'s time on this project's 2-core VM. Buffers of 2 MB and up asked for as
// transparent huge pages fault once per 2 MB. The kernel's default policy on Debian is
// `madvise`: huge pages only where a process asks.
#pragma once

namespace vellum {

// Sets this process up for one run of the pipeline over a scan (`vellum process`):
// - every cv::Mat of 2 MB or more asks the kernel for transparent huge pages: its block is
//   aligned to 2 MB and advised MADV_HUGEPAGE, and a freed block is kept (up to 256 MB in all)
//   for the next Mat it holds (the block's tail beyond that Mat given back), so a stage's images
//   reuse the last stage's pages. A Mat that no kept block holds gives back as many kept bytes
//   as it maps, the smallest blocks first: the kept never raise the process's peak. Where
//   the kernel gives no huge pages (policy `never`) only the alignment and the reuse remain;
// - glibc keeps the rest of what is freed (buffers under 32 MB come from its heap, which is not
//   given back under 256 MB) instead of mapping every buffer of 128 kB and up apart.
// Smaller Mats, and Mats over memory they do not own, are as OpenCV makes them. Call once,
// before the work. A long-lived daemon need not: its buffers live from scan to scan.
void UseMemoryForOneRun();

}  // namespace vellum
