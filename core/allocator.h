// Process-wide settings of the C allocator for crease's commands.
//
// crease works on many full-size float maps (a 1024² CV_32F map is 4 MB, an RGB
// one 12 MB) that a frame loop allocates and frees every frame. glibc serves blocks
// above its mmap threshold (128 KB, raised adaptively) with fresh mmap pages and
// trims the heap's free top back to the kernel above its trim threshold, so every
// such allocation faults its pages in again: `crease eval` on a 211-frame
// paper-size sequence took 2.9 M minor page faults (14 % of its time in the
// kernel). KeepLargeBlocksInHeap raises both thresholds so freed maps are reused
// from the heap instead.
//
// Measured (crease eval, paper profile, 211 frames, 2-vCPU AMD EPYC, idle):
// 140 s → 111 s, 2.9–3.6 M → 0.26 M minor faults, peak RSS unchanged (1.26 GB);
// eval.json and eval_frames.csv byte-identical. Outputs never depend on it.
#pragma once

namespace crease {

// Sets glibc's mmap threshold to its maximum (32 MB on 64-bit) and the trim
// threshold to 1 GB. Call once at the start of a program, before threads start.
// Returns false (and does nothing) on a C library without mallopt.
bool KeepLargeBlocksInHeap();

}  // namespace crease
