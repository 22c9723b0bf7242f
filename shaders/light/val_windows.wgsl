// The VAL buffer as uniform windows (`light::val_windows`): a kernel that reads the VALs in
// list order, every invocation the same VAL at each step, binds them as group 2 and runs one
// dispatch per window. On a CPU device a uniform load at an offset every lane shares is one
// load and a broadcast, where a load from a storage buffer or workgroup memory is one per lane
// (`src/vals/README.md`, "How lavapipe loads memory").
#include "vals_common.wgsl"

// VALs per window (`VAL_WINDOW` in `src/light/rsm.rs`, which pads the VAL buffer to whole
// windows): 48 KiB, under the 64 KiB a uniform binding may hold.
const WINDOW_VALS: u32 = 1024u;

// `ValWindow` in `src/light/val_windows.rs`: which window a dispatch reads.
struct ValWindow {
    // Index of the window's first VAL.
    first: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// Both at a dynamic offset: the VALs from `window.first` on, and the window's record.
@group(2) @binding(0) var<uniform> window_vals: array<Val, WINDOW_VALS>;
@group(2) @binding(1) var<uniform> window: ValWindow;

// True when this dispatch's window starts past the frame's `count` VALs: it has nothing to
// add. Never for window 0, which always runs so that a frame without VALs still writes its
// outputs.
fn window_past_count(count: u32) -> bool {
    return window.first > 0u && window.first >= count;
}

// One past the last of the frame's `count` VALs in this dispatch's window.
fn window_end(count: u32) -> u32 {
    return min(window.first + WINDOW_VALS, count);
}
