//! Headers that declare huge sizes must not make the loader allocate them.
//!
//! This test binary installs a counting global allocator (hence its own file:
//! it would disturb no other test, but it counts every thread's allocations,
//! so the binary holds a single test) and loads each file of the broken
//! corpus, `fixtures/weights/broken/` (see `broken_corpus.rs`), checking the
//! peak of live heap bytes while doing so.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use picker_nets::{Net, Weights};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(size: usize) {
    let live = LIVE.fetch_add(size, Ordering::SeqCst) + size;
    PEAK.fetch_max(live, Ordering::SeqCst);
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        LIVE.fetch_sub(layout.size(), Ordering::SeqCst);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::SeqCst);
            grew(new_size);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Live heap bytes a load may add: the largest corpus file is 74 KB, and a
/// tiny network's folded weights are a few hundred KB.
const LIMIT: usize = 4 << 20;

/// Peak live heap bytes above those live before, while running `f`.
fn peak_during(f: impl FnOnce()) -> usize {
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    f();
    PEAK.load(Ordering::SeqCst) - before
}

/// The one test of this binary (see the module docs).
#[test]
fn loading_broken_files_allocates_little() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/weights/broken");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .expect("fixtures/weights/broken exists")
        .map(|e| e.expect("listing the corpus").path())
        .filter(|p| p.file_name().is_some_and(|n| n != "README.md"))
        .collect();
    paths.sort();
    // The files whose headers declare huge sizes must be among them.
    for f in [
        "header_len_huge.safetensors",
        "header_len_1tb.safetensors",
        "tensor_shape_huge.safetensors",
        "tensor_shape_large.safetensors",
        "offsets_out_of_range.safetensors",
        "offsets_overflow.safetensors",
    ] {
        assert!(
            paths.contains(&dir.join(f)),
            "{f} is missing from the corpus"
        );
    }
    let mut report = Vec::new();
    for path in &paths {
        let bytes = std::fs::read(path).expect("reading a corpus file");
        let name = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let opened = peak_during(|| {
            // broken_corpus.rs checks the messages; `wrong_net` (a valid MSN) loads here.
            let _ = Weights::open(path).and_then(|w| Net::load(&w).map(drop));
        });
        let len = bytes.len();
        let in_memory = peak_during(|| {
            // The bytes themselves are live before and counted in neither peak.
            let _ =
                Weights::from_bytes("mem.safetensors", bytes).and_then(|w| Net::load(&w).map(drop));
        });
        println!("{name}: {len} bytes, peak heap {opened} (open), {in_memory} (from_bytes)");
        report.push((name, opened.max(in_memory)));
    }
    let too_big: Vec<_> = report.iter().filter(|(_, peak)| *peak > LIMIT).collect();
    assert!(
        too_big.is_empty(),
        "loading these allocated more than {LIMIT} bytes at the peak: {too_big:?}"
    );
}
