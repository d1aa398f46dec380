// How a process holds its large images: the kernel's huge pages for them.
//
// A 1600 x 1200 scan's pipeline touches some 240 MB of fresh buffers. On a 4 kB page each first
// touch faults (60 000 faults), and under a hypervisor each fault is dear: a quarter of
// `vellum process`'s time on this project's 2-core VM. Buffers of 2 MB and up asked for as
// transparent huge pages fault once per 2 MB. The kernel's default policy on Debian is
// `madvise`: huge pages only where a process asks.
#pragma once

namespace vellum {

// Makes every cv::Mat of 2 MB or more (from here on, in this process) ask the kernel for
// transparent huge pages: its block is aligned to 2 MB and advised MADV_HUGEPAGE. Smaller Mats,
// and Mats that wrap memory they do not own, are as OpenCV makes them. Where the kernel gives
// no huge pages (policy `never`), nothing changes but the alignment. Call once, before the work.
void UseHugePagesForLargeImages();

}  // namespace vellum
