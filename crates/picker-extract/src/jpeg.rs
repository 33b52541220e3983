//! A check of a JPEG file's entropy-coded data, block by block, without
//! decoding pixels.
//!
//! JPEG decoders are lenient by design: the `image` crate's decoder (like
//! libjpeg) fills the blocks a damaged or cut file does not hold with the
//! last colour it decoded, and decodes a scan whose bytes were changed into
//! whatever the changed bits say, with no error. A photo with its middle cut
//! out (an end-of-image marker after half the data) or a few bytes flipped
//! would silently become a material extracted from garbage. [`check`] walks
//! the Huffman codes of every block of every scan of a Huffman-coded
//! **sequential** (baseline, extended) or **progressive** JPEG (Annex G:
//! DC and AC scans, first and refining, end-of-band runs, each coefficient's
//! history kept for the refining AC scans) and reports:
//!
//! - data that ends (at a marker) before the frame's last block;
//! - a code that no Huffman table of the scan holds, a coefficient size past
//!   the precision's limit, a run of zeros past a block's (or the band's)
//!   last coefficient, a refining scan's coefficient of size other than 1;
//! - a restart marker missing or out of order where the restart interval
//!   (DRI) puts one, or whole bytes left over before it;
//! - whole bytes left over after the scan's last block (the bit stream went
//!   out of step somewhere: a damaged byte the codes happened to absorb);
//! - a colour component no scan covers.
//!
//! Corruption that keeps every code valid and the bit count exact is not
//! seen (it is rare: a changed bit almost always moves the codes' boundaries
//! until the end of the scan or the next restart marker). Lossless,
//! hierarchical and arithmetic-coded files and files whose height comes in
//! a DNL marker are not walked ([`Checked::NotWalked`]); neither is
//! anything the marker structure leaves unclear (the decoder then speaks for
//! itself). Reading costs about as much as one pass over the bytes with a
//! table lookup per code (tens of milliseconds for a 12-megapixel photo).

/// What [`check`] did with a JPEG file it found no fault in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Checked {
    /// Every block of every scan was walked and the data fits the frame.
    Walked,
    /// The file's coding is not one this check walks (lossless,
    /// hierarchical, arithmetic, a DNL height, an unclear marker structure).
    NotWalked,
}

/// A fault in a JPEG file's entropy-coded data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Damage {
    /// The data ends (at a marker, or at the end of the file) before the
    /// frame's last block: decoders fill the rest.
    EndsEarly(String),
    /// The data cannot be what an encoder wrote.
    Corrupt(String),
}

/// Walks the entropy-coded data of the JPEG file `bytes` (see the module
/// docs). `Ok` when nothing is wrong or the file is not walked.
///
/// Memory: a progressive file's AC history takes 8 bytes per block of each
/// component it refines (12 MB for a 100-megapixel picture, but 512 MB for
/// a lying 65535 × 65535 header): [`crate::photo`] calls this only after the
/// header's size has passed its limits.
pub fn check(bytes: &[u8]) -> Result<Checked, Damage> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Ok(Checked::NotWalked);
    }
    let mut tables = Tables::default();
    let mut frame: Option<Frame> = None;
    let mut restart_interval = 0usize;
    let mut i = 2;
    loop {
        // Fill bytes before a marker.
        while bytes.get(i) == Some(&0xFF) && bytes.get(i + 1) == Some(&0xFF) {
            i += 1;
        }
        if bytes.get(i).is_some_and(|&b| b != 0xFF) {
            // Extraneous bytes before a marker: decoders skip them to the
            // next one (libjpeg warns), and so does the walk.
            match bytes[i..].iter().position(|&b| b == 0xFF) {
                Some(k) => {
                    i += k;
                    continue;
                }
                None => return Ok(Checked::NotWalked),
            }
        }
        let (Some(&0xFF), Some(&m)) = (bytes.get(i), bytes.get(i + 1)) else {
            return Ok(Checked::NotWalked);
        };
        i += 2;
        if m == 0xD9 {
            // End of image: every component must have had its scan.
            return match &frame {
                Some(f) => match f.comps.iter().position(|c| !c.scanned) {
                    Some(k) => Err(Damage::EndsEarly(format!(
                        "the image ends before the data of colour component {} of {}",
                        k + 1,
                        f.comps.len()
                    ))),
                    None => Ok(Checked::Walked),
                },
                None => Ok(Checked::NotWalked),
            };
        }
        if m == 0x01 || (0xD0..=0xD8).contains(&m) {
            continue; // No length: TEM, a stray restart marker, SOI.
        }
        let past_end = || {
            Damage::EndsEarly(format!(
                "the file ends inside the segment of marker FF {m:02X} at byte {}",
                i - 2
            ))
        };
        let len = bytes
            .get(i..i + 2)
            .map(|l| u16::from_be_bytes([l[0], l[1]]) as usize)
            .ok_or_else(past_end)?;
        if len < 2 {
            return Ok(Checked::NotWalked);
        }
        let seg = bytes.get(i + 2..i + len).ok_or_else(past_end)?;
        i += len;
        match m {
            0xC4 => tables.read(seg)?,
            0xDB => tables.read_quant(seg)?,
            0xDD => match seg {
                [hi, lo, ..] => restart_interval = u16::from_be_bytes([*hi, *lo]) as usize,
                _ => return Ok(Checked::NotWalked),
            },
            0xC0..=0xC2 => match Frame::read(seg, m == 0xC2)? {
                Some(f) if frame.is_none() => frame = Some(f),
                _ => return Ok(Checked::NotWalked),
            },
            // Lossless, hierarchical, arithmetic: not walked.
            0xC3 | 0xC5..=0xC7 | 0xC9..=0xCB | 0xCD..=0xCF => return Ok(Checked::NotWalked),
            0xDA => {
                let Some(f) = frame.as_mut() else {
                    return Ok(Checked::NotWalked);
                };
                let scan = Scan::read(seg, f, &tables)?;
                i = walk_scan(bytes, i, f, &scan, &tables, restart_interval)?;
                for &(k, ..) in &scan.comps {
                    f.comps[k].scanned = true;
                }
            }
            _ => {} // Tables, comments, application data: skipped.
        }
    }
}

/// One colour component of the frame.
struct Comp {
    id: u8,
    h: usize,
    v: usize,
    /// Its quantisation table.
    tq: usize,
    scanned: bool,
    /// Progressive only: per block (in the component's own raster, as a
    /// one-component scan codes it), a bit per coefficient that earlier
    /// scans made nonzero. Empty until a refining AC scan needs it.
    nonzero: Vec<u64>,
}

/// The frame header (SOF0/SOF1/SOF2).
struct Frame {
    precision: u8,
    height: usize,
    width: usize,
    comps: Vec<Comp>,
    progressive: bool,
}

impl Frame {
    /// `Ok(None)` for a header this check does not take (a DNL height);
    /// `Err` for one no encoder writes.
    fn read(seg: &[u8], progressive: bool) -> Result<Option<Self>, Damage> {
        let bad = |what: &str| Damage::Corrupt(format!("the frame header {what}"));
        let short = || bad("is cut short");
        let (&precision, rest) = seg.split_first().ok_or_else(short)?;
        let [h0, h1, w0, w1, n, ..] = *rest else {
            return Err(short());
        };
        let (height, width) = (
            u16::from_be_bytes([h0, h1]) as usize,
            u16::from_be_bytes([w0, w1]) as usize,
        );
        let n = n as usize;
        if !matches!(precision, 8 | 12) {
            return Err(bad(&format!("states {precision}-bit samples (8 or 12)")));
        }
        if width == 0 || n == 0 || n > 4 {
            return Err(bad(&format!("states {width} columns and {n} components")));
        }
        if height == 0 {
            return Ok(None); // The height comes in a DNL marker.
        }
        let comps = (0..n)
            .map(|k| {
                let c = rest.get(5 + 3 * k..8 + 3 * k).ok_or_else(short)?;
                let (h, v) = ((c[1] >> 4) as usize, (c[1] & 15) as usize);
                if !((1..=4).contains(&h) && (1..=4).contains(&v) && c[2] < 4) {
                    return Err(bad(
                        "states a sampling factor outside 1–4 or a table over 3",
                    ));
                }
                Ok(Comp {
                    id: c[0],
                    h,
                    v,
                    tq: c[2] as usize,
                    scanned: false,
                    nonzero: Vec::new(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Some(Self {
            precision,
            height,
            width,
            comps,
            progressive,
        }))
    }

    fn h_max(&self) -> usize {
        self.comps.iter().map(|c| c.h).max().unwrap_or(1)
    }

    fn v_max(&self) -> usize {
        self.comps.iter().map(|c| c.v).max().unwrap_or(1)
    }

    /// Component `k`'s blocks `(columns, rows)` as a one-component scan
    /// codes them (A.2.2: its samples, not padded to whole MCUs).
    fn blocks(&self, k: usize) -> (usize, usize) {
        let c = &self.comps[k];
        (
            (self.width * c.h).div_ceil(self.h_max()).div_ceil(8),
            (self.height * c.v).div_ceil(self.v_max()).div_ceil(8),
        )
    }
}

/// A scan header (SOS).
struct Scan {
    /// `(component index in the frame, DC table, AC table)`.
    comps: Vec<(usize, usize, usize)>,
    /// The spectral band's first and last coefficient.
    ss: usize,
    se: usize,
    /// Successive approximation: nonzero for a refining scan; the point
    /// transform (bits dropped).
    ah: u8,
    al: u8,
}

impl Scan {
    /// `Err` for a header no encoder writes for this frame (a band or
    /// component count the frame's coding does not allow, an unknown
    /// component, a table the scan needs never defined).
    fn read(seg: &[u8], frame: &Frame, tables: &Tables) -> Result<Self, Damage> {
        let bad = |what: &str| Damage::Corrupt(format!("a scan header {what}"));
        let n = *seg.first().ok_or_else(|| bad("is empty"))? as usize;
        let tail = seg
            .get(1 + 2 * n..4 + 2 * n)
            .ok_or_else(|| bad("is cut short"))?;
        let (ss, se, ah, al) = (
            tail[0] as usize,
            tail[1] as usize,
            tail[2] >> 4,
            tail[2] & 15,
        );
        let band_ok = if frame.progressive {
            // DC alone (any components) or one component's AC band.
            ss <= se && se <= 63 && ((ss == 0 && se == 0) || (ss > 0 && n == 1)) && al <= 13
        } else {
            (ss, se, ah, al) == (0, 63, 0, 0)
        };
        if !band_ok || n == 0 || n > 4 {
            return Err(bad(&format!(
                "states {n} components, coefficients {ss}–{se}, approximation {ah}/{al}"
            )));
        }
        // The tables the scan decodes with: none for a DC refinement.
        let (need_dc, need_ac) = (ss == 0 && ah == 0, se > 0);
        let comps = (0..n)
            .map(|k| {
                let c = &seg[1 + 2 * k..3 + 2 * k];
                let idx = frame
                    .comps
                    .iter()
                    .position(|fc| fc.id == c[0])
                    .ok_or_else(|| {
                        bad(&format!(
                            "names component {}, which the frame has not",
                            c[0]
                        ))
                    })?;
                let (td, ta) = ((c[1] >> 4) as usize, (c[1] & 15) as usize);
                let has =
                    |t: &[Option<Huffman>; 4], i: usize| t.get(i).is_some_and(Option::is_some);
                if (need_dc && !has(&tables.dc, td)) || (need_ac && !has(&tables.ac, ta)) {
                    return Err(bad("uses a Huffman table never defined"));
                }
                Ok((idx, td, ta))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            comps,
            ss,
            se,
            ah,
            al,
        })
    }
}

/// The Huffman tables defined so far (DC and AC, four each) and the DC
/// step of each quantisation table.
#[derive(Default)]
struct Tables {
    dc: [Option<Huffman>; 4],
    ac: [Option<Huffman>; 4],
    dc_step: [Option<u16>; 4],
}

impl Tables {
    /// Reads a DQT segment's DC steps; `Err` for one no encoder writes (a
    /// precision over 16 bits, a table id over 3, a short segment).
    fn read_quant(&mut self, mut seg: &[u8]) -> Result<(), Damage> {
        while let Some((&pq_tq, rest)) = seg.split_first() {
            let (wide, id) = (pq_tq >> 4, (pq_tq & 15) as usize);
            let len = if wide == 1 { 128 } else { 64 };
            let (Some(values), true) = (rest.get(..len), id < 4 && wide < 2) else {
                return Err(Damage::Corrupt(
                    "a quantisation table segment is cut short or names a table over 3".into(),
                ));
            };
            let step = if wide == 1 {
                u16::from_be_bytes([values[0], values[1]])
            } else {
                u16::from(values[0])
            };
            self.dc_step[id] = (step > 0).then_some(step);
            seg = &rest[len..];
        }
        Ok(())
    }

    /// Reads a DHT segment; `Err` for one no encoder writes (a class over
    /// 1, a table id over 3, more codes than the segment or their lengths
    /// hold).
    fn read(&mut self, mut seg: &[u8]) -> Result<(), Damage> {
        let bad = |what: &str| Damage::Corrupt(format!("a Huffman table segment {what}"));
        while let Some((&tc_th, rest)) = seg.split_first() {
            let (class, id) = ((tc_th >> 4) as usize, (tc_th & 15) as usize);
            let counts = rest.get(..16).ok_or_else(|| bad("is cut short"))?;
            let total: usize = counts.iter().map(|&c| c as usize).sum();
            let values = rest
                .get(16..16 + total)
                .ok_or_else(|| bad("is cut short"))?;
            if class > 1 || id > 3 {
                return Err(bad(&format!("names table class {class} id {id}")));
            }
            let table = Huffman::new(counts, values).ok_or_else(|| {
                Damage::Corrupt(format!(
                    "Huffman table {} {id} has more codes than its lengths allow",
                    if class == 0 { "DC" } else { "AC" }
                ))
            })?;
            if class == 0 {
                self.dc[id] = Some(table);
            } else {
                self.ac[id] = Some(table);
            }
            seg = &rest[16 + total..];
        }
        Ok(())
    }
}

/// Bits a code's first lookup covers.
const LOOKUP_BITS: u32 = 9;

/// A canonical Huffman code (JPEG Annex C / F.2.2.3).
struct Huffman {
    /// For each `LOOKUP_BITS`-bit prefix: `(length, symbol)` of the code it
    /// starts with, length 0 when the code is longer.
    lookup: Vec<(u8, u8)>,
    /// Per length `l` (index `l`): the largest code of that length, −1 when
    /// there is none.
    max_code: [i32; 17],
    /// Per length: the index in `values` of its first code, minus that code.
    offset: [i32; 17],
    values: Vec<u8>,
}

impl Huffman {
    /// `None` when the counts ask for more codes than their lengths hold.
    fn new(counts: &[u8], values: &[u8]) -> Option<Self> {
        let mut max_code = [-1i32; 17];
        let mut offset = [0i32; 17];
        let mut lookup = vec![(0u8, 0u8); 1 << LOOKUP_BITS];
        let (mut code, mut k) = (0i32, 0usize);
        for l in 1..=16usize {
            let n = counts[l - 1] as usize;
            if n > 0 {
                offset[l] = k as i32 - code;
                for _ in 0..n {
                    if code >= 1 << l {
                        return None;
                    }
                    if l as u32 <= LOOKUP_BITS {
                        let shift = LOOKUP_BITS - l as u32;
                        let start = (code as usize) << shift;
                        for e in &mut lookup[start..start + (1 << shift)] {
                            *e = (l as u8, values[k]);
                        }
                    }
                    code += 1;
                    k += 1;
                }
                max_code[l] = code - 1;
            }
            code <<= 1;
        }
        Some(Self {
            lookup,
            max_code,
            offset,
            values: values.to_vec(),
        })
    }

    /// The symbol whose code starts the 16 bits `peek`, and its length;
    /// `None` for bits no code of the table starts.
    fn decode(&self, peek: u32) -> Option<(u32, u8)> {
        let (len, sym) = self.lookup[(peek >> (16 - LOOKUP_BITS)) as usize];
        if len > 0 {
            return Some((u32::from(len), sym));
        }
        for l in LOOKUP_BITS as usize + 1..=16 {
            let code = (peek >> (16 - l)) as i32;
            if code <= self.max_code[l] {
                let at = (code + self.offset[l]) as usize;
                return self.values.get(at).map(|&s| (l as u32, s));
            }
        }
        None
    }
}

/// The entropy-coded bytes of one scan, read as bits (stuffed `FF 00`
/// bytes undone), stopping at the first marker.
struct Bits<'a> {
    bytes: &'a [u8],
    /// The next byte to load.
    pos: usize,
    /// Loaded bits, the next one highest.
    buf: u64,
    count: u32,
    /// Where the marker that ends the data starts, once reached.
    marker: Option<usize>,
}

impl<'a> Bits<'a> {
    fn new(bytes: &'a [u8], pos: usize) -> Self {
        Self {
            bytes,
            pos,
            buf: 0,
            count: 0,
            marker: None,
        }
    }

    /// Loads bytes until 57 bits are held or the data ends.
    fn fill(&mut self) {
        while self.count <= 56 && self.marker.is_none() {
            let byte = match (self.bytes.get(self.pos), self.bytes.get(self.pos + 1)) {
                (None, _) => {
                    self.marker = Some(self.pos);
                    break;
                }
                (Some(&0xFF), Some(&0x00)) => {
                    self.pos += 2;
                    0xFF
                }
                (Some(&0xFF), _) => {
                    // Fill bytes, then the marker.
                    let mut at = self.pos;
                    while self.bytes.get(at + 1) == Some(&0xFF) {
                        at += 1;
                    }
                    self.marker = Some(at);
                    break;
                }
                (Some(&b), _) => {
                    self.pos += 1;
                    b
                }
            };
            self.buf |= u64::from(byte) << (56 - self.count);
            self.count += 8;
        }
    }

    /// The next 16 bits (zeros past the end of the data).
    fn peek16(&mut self) -> u32 {
        if self.count < 16 {
            self.fill();
        }
        (self.buf >> 48) as u32
    }

    /// Drops `n` bits (≤ 16); `false` when the data holds fewer.
    fn consume(&mut self, n: u32) -> bool {
        if self.count < n {
            self.fill();
            if self.count < n {
                return false;
            }
        }
        self.buf <<= n;
        self.count -= n;
        true
    }

    /// Whole data bytes between the current bit and the marker (the bits of
    /// a partly read byte are padding), and the marker's position (`None`
    /// at the end of the file).
    fn skip_to_marker(&mut self) -> (usize, Option<usize>) {
        let mut whole = (self.count / 8) as usize;
        self.buf = 0;
        self.count = 0;
        loop {
            self.fill();
            if let Some(at) = self.marker {
                whole += (self.count / 8) as usize;
                self.buf = 0;
                self.count = 0;
                return (whole, (at < self.bytes.len()).then_some(at));
            }
            whole += (self.count / 8) as usize;
            self.buf = 0;
            self.count = 0;
        }
    }
}

/// Walks one scan starting at `start` (after its header); the position of
/// the marker that ends it. A progressive AC scan updates its component's
/// coefficient history.
fn walk_scan(
    bytes: &[u8],
    start: usize,
    frame: &mut Frame,
    scan: &Scan,
    tables: &Tables,
    restart_interval: usize,
) -> Result<usize, Damage> {
    let (hm, vm) = (frame.h_max(), frame.v_max());
    // Blocks per MCU (component, DC table, AC table) and the MCU grid.
    let (units, mcu_cols, mcu_rows) = if let [(k, td, ta)] = scan.comps[..] {
        // One component: its blocks in raster order, one per MCU.
        let (cols, rows) = frame.blocks(k);
        (vec![(k, td, ta)], cols, rows)
    } else {
        let units = scan
            .comps
            .iter()
            .flat_map(|&(k, td, ta)| {
                std::iter::repeat_n((k, td, ta), frame.comps[k].h * frame.comps[k].v)
            })
            .collect();
        (
            units,
            frame.width.div_ceil(8 * hm),
            frame.height.div_ceil(8 * vm),
        )
    };
    let limits = if frame.precision == 8 {
        Limits { dc: 11, ac: 10 }
    } else {
        Limits { dc: 15, ac: 14 }
    };
    let mcus = mcu_cols * mcu_rows;
    // Only one-component (AC) scans use the history: its index is the MCU's.
    let band = frame.progressive && scan.ss > 0;
    if band {
        let k = scan.comps[0].0;
        if frame.comps[k].nonzero.is_empty() {
            frame.comps[k].nonzero = vec![0; mcus];
        }
    }
    let row_of = |m: usize| format!("MCU row {} of {mcu_rows}", m / mcu_cols + 1);
    let mut bits = Bits::new(bytes, start);
    let mut next_restart = 0u8;
    let mut eob_run = 0u32;
    // Each component's DC value so far (in units of the scan's point
    // transform) and the largest magnitude its quantisation step allows:
    // the DCT's DC term of 8-bit samples lies within ±1024 (±16384 for 12-bit).
    let mut dc_value = vec![0i64; frame.comps.len()];
    let dc_bound: Vec<Option<i64>> = frame
        .comps
        .iter()
        .map(|c| {
            let range = if frame.precision == 8 { 1024 } else { 16384 };
            tables.dc_step[c.tq].map(|q| {
                let unit = i64::from(q) << scan.al;
                (range + unit) / unit
            })
        })
        .collect();
    for m in 0..mcus {
        if restart_interval > 0 && m > 0 && m % restart_interval == 0 {
            let (left, marker) = bits.skip_to_marker();
            let want = 0xD0 + next_restart;
            match marker.map(|at| (at, bytes.get(at + 1).copied())) {
                Some((at, Some(found))) if found == want && left == 0 => {
                    bits = Bits::new(bytes, at + 2);
                    next_restart = (next_restart + 1) % 8;
                    eob_run = 0;
                    dc_value.fill(0);
                }
                Some((_, Some(found))) if found == want => {
                    return Err(Damage::Corrupt(format!(
                        "{left} bytes of image data left over before restart marker {} ({}): the data is out of step",
                        next_restart,
                        row_of(m)
                    )))
                }
                Some((_, Some(0xD0..=0xD7))) => {
                    return Err(Damage::Corrupt(format!(
                        "restart marker {next_restart} is missing or out of order ({})",
                        row_of(m)
                    )))
                }
                _ => return Err(Damage::EndsEarly(format!("the image data stops in {}", row_of(m)))),
            }
        }
        for &(k, td, ta) in &units {
            let missing = Fault::Bad;
            let (dc, ac) = (
                tables.dc.get(td).and_then(Option::as_ref),
                tables.ac.get(ta).and_then(Option::as_ref),
            );
            let dc = || dc.ok_or(missing("a missing Huffman table"));
            let ac = || ac.ok_or(missing("a missing Huffman table"));
            let mut walk = || -> Result<(), Fault> {
                if !frame.progressive || (scan.ss == 0 && scan.ah == 0) {
                    dc_value[k] += dc_first_block(&mut bits, dc()?, limits)?;
                    if dc_bound[k].is_some_and(|b| dc_value[k].abs() > b) {
                        return Err(Fault::Bad("a DC value out of its samples' range"));
                    }
                    if frame.progressive {
                        Ok(())
                    } else {
                        sequential_ac(&mut bits, ac()?, limits)
                    }
                } else if scan.ss == 0 {
                    bits.get(1).map(drop)
                } else {
                    let nonzero = &mut frame.comps[k].nonzero[m];
                    let band = (scan.ss, scan.se);
                    if scan.ah == 0 {
                        ac_first_block(&mut bits, ac()?, band, limits, &mut eob_run, nonzero)
                    } else {
                        ac_refine_block(&mut bits, ac()?, band, &mut eob_run, nonzero)
                    }
                }
            };
            if let Err(fault) = walk() {
                return Err(match fault {
                    Fault::Ends => {
                        Damage::EndsEarly(format!("the image data stops in {}", row_of(m)))
                    }
                    Fault::Bad(what) => Damage::Corrupt(format!("{what} in {}", row_of(m))),
                });
            }
        }
    }
    let (left, marker) = bits.skip_to_marker();
    let Some(at) = marker else {
        // The file ends in the scan: the caller's own check reports it.
        return Ok(bytes.len());
    };
    if left > 0 {
        return Err(Damage::Corrupt(format!(
            "{left} bytes of image data left over after the last block: the data is out of step"
        )));
    }
    Ok(at)
}

/// Why a block could not be walked.
#[derive(Debug)]
enum Fault {
    /// The data ended.
    Ends,
    /// The codes cannot be an encoder's.
    Bad(&'static str),
}

/// The largest coefficient sizes (bits) the frame's precision allows.
#[derive(Clone, Copy)]
struct Limits {
    dc: u8,
    ac: u8,
}

impl Bits<'_> {
    /// The next `n` bits (≤ 16) as a number.
    fn get(&mut self, n: u32) -> Result<u32, Fault> {
        if n == 0 {
            return Ok(0);
        }
        let value = self.peek16() >> (16 - n);
        if self.consume(n) {
            Ok(value)
        } else {
            Err(Fault::Ends)
        }
    }

    /// The next symbol of `table`.
    fn symbol(&mut self, table: &Huffman) -> Result<u8, Fault> {
        let Some((len, sym)) = table.decode(self.peek16()) else {
            // Past the data's end the bits are made-up zeros.
            return Err(if self.count < 16 {
                Fault::Ends
            } else {
                Fault::Bad("a code no Huffman table holds")
            });
        };
        if self.consume(len) {
            Ok(sym)
        } else {
            Err(Fault::Ends)
        }
    }
}

/// A block's DC difference (sequential, or a progressive first DC scan).
fn dc_first_block(bits: &mut Bits, dc: &Huffman, limits: Limits) -> Result<i64, Fault> {
    let size = bits.symbol(dc)?;
    if size > limits.dc {
        return Err(Fault::Bad(
            "a DC difference larger than the precision allows",
        ));
    }
    let v = i64::from(bits.get(u32::from(size))?);
    // F.2.2.1 EXTEND: a leading 0 bit means a negative difference.
    Ok(if size > 0 && v < 1 << (size - 1) {
        v - (1 << size) + 1
    } else {
        v
    })
}

/// A sequential 8 × 8 block's AC coefficients.
fn sequential_ac(bits: &mut Bits, ac: &Huffman, limits: Limits) -> Result<(), Fault> {
    let mut eob_run = 0;
    let mut nonzero = 0;
    ac_first_block(bits, ac, (1, 63), limits, &mut eob_run, &mut nonzero)?;
    // A sequential block has no end-of-band runs longer than itself.
    if eob_run > 0 {
        return Err(Fault::Bad("an end-of-band run in a sequential scan"));
    }
    Ok(())
}

/// One block of a first AC scan of the band `(ss, se)` (G.1.2.2; a
/// sequential block's AC part is the band 1–63 with no runs over blocks):
/// its nonzero coefficients are set in `nonzero`.
fn ac_first_block(
    bits: &mut Bits,
    ac: &Huffman,
    (ss, se): (usize, usize),
    limits: Limits,
    eob_run: &mut u32,
    nonzero: &mut u64,
) -> Result<(), Fault> {
    if *eob_run > 0 {
        *eob_run -= 1;
        return Ok(());
    }
    let mut k = ss;
    while k <= se {
        let rs = bits.symbol(ac)?;
        let (run, size) = ((rs >> 4) as usize, rs & 15);
        if size == 0 {
            if run < 15 {
                // End of band, here and in the next `2^run − 1 + bits` blocks.
                *eob_run = (1u32 << run) - 1 + bits.get(run as u32)?;
                break;
            }
            k += 16;
            if k > se + 1 {
                return Err(Fault::Bad("a run of zeros past the band's end"));
            }
            continue;
        }
        k += run;
        if k > se {
            return Err(Fault::Bad("a run of zeros past the band's end"));
        }
        if size > limits.ac {
            return Err(Fault::Bad(
                "an AC coefficient larger than the precision allows",
            ));
        }
        bits.get(u32::from(size))?;
        *nonzero |= 1 << k;
        k += 1;
    }
    Ok(())
}

/// One block of a refining AC scan of the band `(ss, se)` (G.1.2.3): a
/// correction bit for each coefficient `nonzero` holds, newly nonzero ones
/// placed on the zero ones (and set in `nonzero`, for the next refinement).
fn ac_refine_block(
    bits: &mut Bits,
    ac: &Huffman,
    (ss, se): (usize, usize),
    eob_run: &mut u32,
    nonzero: &mut u64,
) -> Result<(), Fault> {
    let set = |nonzero: u64, k: usize| (nonzero >> k) & 1 == 1;
    let mut k = ss;
    if *eob_run == 0 {
        while k <= se {
            let rs = bits.symbol(ac)?;
            let (mut run, size) = ((rs >> 4) as i32, rs & 15);
            if size == 0 && run < 15 {
                *eob_run = (1u32 << run) + bits.get(run as u32)?;
                break;
            }
            if size > 1 {
                return Err(Fault::Bad("a refining coefficient of size other than 1"));
            }
            if size == 1 {
                bits.get(1)?; // Its sign.
            }
            // Past `run` zero coefficients (correcting the nonzero ones on
            // the way) to the one the new coefficient, or the run's end, is.
            loop {
                if k > se {
                    return Err(Fault::Bad("a run of zeros past the band's end"));
                }
                if set(*nonzero, k) {
                    bits.get(1)?;
                } else {
                    run -= 1;
                    if run < 0 {
                        break;
                    }
                }
                k += 1;
            }
            if size == 1 {
                *nonzero |= 1 << k;
            }
            k += 1;
        }
    }
    if *eob_run > 0 {
        while k <= se {
            if set(*nonzero, k) {
                bits.get(1)?;
            }
            k += 1;
        }
        *eob_run -= 1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The codes of a table by the standard's own procedure (C.1, C.2:
    /// HUFFSIZE and HUFFCODE), `(length, code, symbol)`.
    fn reference_codes(counts: &[u8; 16], values: &[u8]) -> Vec<(u32, u32, u8)> {
        let mut sizes = Vec::new();
        for (l, &n) in counts.iter().enumerate() {
            sizes.extend(std::iter::repeat_n(l as u32 + 1, n as usize));
        }
        let mut out = Vec::new();
        let (mut code, mut si) = (0u32, sizes.first().copied().unwrap_or(0));
        for (k, &size) in sizes.iter().enumerate() {
            while size > si {
                code <<= 1;
                si += 1;
            }
            out.push((size, code, values[k]));
            code += 1;
        }
        out
    }

    /// Random valid tables (code lengths whose Kraft sum stays below 1):
    /// every code decodes to its symbol whatever bits follow it, and a word
    /// no code starts is refused.
    #[test]
    fn huffman_decode_matches_the_standards_codes() {
        let mut rng = picker_tensor::Rng::new(7);
        for case in 0..300 {
            // Draw lengths, keeping the Kraft sum under 1 (the all-ones
            // code of the longest length stays free, as encoders keep it).
            let mut counts = [0u8; 16];
            let mut kraft = 0.0f64;
            let codes = rng.range(1, 200);
            let max_len = rng.range(1, 16) as u32;
            for _ in 0..codes {
                let l = rng.range(1, max_len as usize);
                let add = 0.5f64.powi(l as i32);
                if kraft + add < 1.0 && counts[l - 1] < 255 {
                    counts[l - 1] += 1;
                    kraft += add;
                }
            }
            let total: usize = counts.iter().map(|&c| c as usize).sum();
            let values: Vec<u8> = (0..total).map(|_| rng.range(0, 255) as u8).collect();
            let table = Huffman::new(&counts, &values).expect("valid lengths");
            let codes = reference_codes(&counts, &values);
            for &(len, code, sym) in &codes {
                for _ in 0..4 {
                    let tail = rng.range(0, (1 << (16 - len)) - 1) as u32;
                    let peek = code << (16 - len) | tail;
                    assert_eq!(
                        table.decode(peek),
                        Some((len, sym)),
                        "case {case}: code {code:b}/{len}"
                    );
                }
            }
            // Words no code starts: past the last code, all lengths padded.
            let (len, code, _) = *codes.last().unwrap();
            let next = (code + 1) << (16 - len);
            if next < 1 << 16 {
                for word in [next, (1 << 16) - 1] {
                    assert_eq!(table.decode(word), None, "case {case}: word {word:016b}");
                }
            }
        }
        // More codes of a length than it holds: refused.
        let mut counts = [0u8; 16];
        counts[1] = 5; // Five 2-bit codes.
        assert!(Huffman::new(&counts, &[0; 5]).is_none());
    }

    /// EXTEND (F.2.2.1) through `dc_first_block`: a size-3 difference with
    /// bits 010 is −5, with 110 it is 6; size 0 is 0.
    #[test]
    fn dc_differences_extend_by_the_standard() {
        // One DC table: size 0 → code 0, size 3 → code 1 (both 1 bit).
        let mut counts = [0u8; 16];
        counts[0] = 2;
        let table = Huffman::new(&counts, &[0, 3]).unwrap();
        let limits = Limits { dc: 11, ac: 10 };
        // Bits: 1 010 | 1 110 | 0 | padding 1s.
        let data = [0b1010_1110, 0b0111_1111, 0xFF, 0xD9];
        let mut bits = Bits::new(&data, 0);
        assert_eq!(dc_first_block(&mut bits, &table, limits).ok(), Some(-5));
        assert_eq!(dc_first_block(&mut bits, &table, limits).ok(), Some(6));
        assert_eq!(dc_first_block(&mut bits, &table, limits).ok(), Some(0));
    }
}
