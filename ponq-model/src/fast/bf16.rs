//! A bf16 GEMM with f32 accumulation, for
//! `Precision::Bf16` (the kernels' precision): `C (+)= A B` where `A` and `B` are rounded to
//! bf16 (round to nearest even) and every product is summed in f32.
//!
//! Two engines, chosen at run time ([`engine`]):
//! - **AMX** (`AMX-BF16` tiles, `tdpbf16ps`: a 16 x 16 f32 block += 16 x 32 by 32 x 16 bf16 per
//!   instruction): many times the f32 FMA rate of the AVX-512 units on CPUs that have it
//!   (Intel Sapphire Rapids and later). Linux grants the tile state per process
//!   (`arch_prctl(ARCH_REQ_XCOMP_PERM)`), asked for once here; the tile instructions are
//!   written as inline assembly because Rust's AMX intrinsics are not stable.
//! - **AVX-512 BF16** (`vdpbf16ps`, 16 lanes of pair dot products) where AMX is absent (or the
//!   environment sets `PONQ_NO_AMX`). On CPUs with both, this one runs at about half the f32
//!   GEMM's rate: it is the fallback, not a speed-up.
//!
//! Why by hand: the `gemm` crate (the f32 path) has no bf16 kernel with f32 accumulation, and
//! no maintained pure-Rust crate drives AMX.
//!
//! Layout: `B` is packed per block of `KCP` pairs of rows into 16-column slabs of bf16 *pairs*
//! (lane `j` of pair `p` holds `B[2p][j]` and `B[2p+1][j]`: the operand order of `vdpbf16ps`,
//! and an AMX `B` tile is 16 consecutive pairs of a slab); `A` into rows of bf16 pairs along
//! `k` (an AMX `A` tile is 16 rows x 16 pairs; one 32-bit broadcast is a pair for AVX-512).
//! Odd `k`, and `m`, `n`, `k` that are not multiples of the tile sizes, are padded with zeros
//! in the packed copies; only the valid part of `C` is read and written.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::cell::RefCell;
use std::sync::OnceLock;

/// The hardware a bf16 GEMM runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    /// AMX tiles (`AMX-BF16`, with AVX-512 F for packing).
    Amx,
    /// AVX-512 BF16 `vdpbf16ps`.
    Avx512,
}

/// The engine this CPU (and OS) runs the bf16 kernel on, or `None` (detected once).
pub fn engine() -> Option<Engine> {
    static ENGINE: OnceLock<Option<Engine>> = OnceLock::new();
    *ENGINE.get_or_init(detect)
}

/// Whether this CPU runs the bf16 kernel at all ([`engine`] is some).
pub fn available() -> bool {
    engine().is_some()
}

#[cfg(target_arch = "x86_64")]
fn detect() -> Option<Engine> {
    if !is_x86_feature_detected!("avx512f") {
        return None;
    }
    if amx_usable() {
        return Some(Engine::Amx);
    }
    is_x86_feature_detected!("avx512bf16").then_some(Engine::Avx512)
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> Option<Engine> {
    None
}

/// AMX-TILE and AMX-BF16 in CPUID (leaf 7: EDX bits 24 and 22), and the OS's permission for
/// this process to use the tile data state.
#[cfg(target_arch = "x86_64")]
fn amx_usable() -> bool {
    if std::env::var_os("PONQ_NO_AMX").is_some() {
        return false;
    }
    let leaf7 = __cpuid_count(7, 0);
    let (bf16, tile) = ((leaf7.edx >> 22) & 1 == 1, (leaf7.edx >> 24) & 1 == 1);
    bf16 && tile && amx_permission()
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn amx_permission() -> bool {
    const ARCH_REQ_XCOMP_PERM: libc::c_long = 0x1023;
    const XFEATURE_XTILEDATA: libc::c_long = 18;
    // SAFETY: a plain system call with integer arguments; it only changes which extended
    // states this process may use.
    let r = unsafe {
        libc::syscall(
            libc::SYS_arch_prctl,
            ARCH_REQ_XCOMP_PERM,
            XFEATURE_XTILEDATA,
        )
    };
    r == 0
}

#[cfg(all(target_arch = "x86_64", not(target_os = "linux")))]
fn amx_permission() -> bool {
    false
}

/// `x` rounded to bf16 (round to nearest, ties to even), as its 16 bits.
#[inline]
pub fn to_bf16(x: f32) -> u16 {
    let b = x.to_bits();
    if x.is_nan() {
        return ((b >> 16) | 0x40) as u16;
    }
    (b.wrapping_add(0x7FFF + ((b >> 16) & 1)) >> 16) as u16
}

/// `x` rounded to bf16 and back to f32 (what the kernel multiplies).
pub fn round_bf16(x: f32) -> f32 {
    f32::from_bits(u32::from(to_bf16(x)) << 16)
}

/// Pairs (`k`) per packed block (a multiple of the AMX tile's 16).
const KCP: usize = 256;
/// Rows per packed block of `A`.
const MC: usize = 96;
/// Rows per AVX-512 micro-kernel panel.
const MR: usize = 12;
/// Packed `A` blocks have a multiple of this many rows (both engines' panels: 12 and 16).
const ROWS_PAD: usize = 48;

thread_local! {
    /// Packing buffers (`A` block, `B` block) reused across calls on this thread.
    static BUFFERS: RefCell<(Vec<u32>, Vec<u32>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// `dst[m, n] (+)= lhs[m, k] * rhs[k, n]` with bf16 inputs and f32 accumulation; strides as in
/// the f32 `mm` (`dst` has column stride 1).
///
/// # Safety
/// [`available`] must be true; the strided extents must lie inside the slices.
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    dst_rs: usize,
    accumulate: bool,
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[f32],
    (rhs_rs, rhs_cs): (usize, usize),
) {
    // SAFETY: the caller's extents (checked inside).
    unsafe {
        gemm_on(
            detected(),
            m,
            n,
            k,
            dst,
            dst_rs,
            accumulate,
            lhs,
            (lhs_rs, lhs_cs),
            Rhs::Strided(rhs, rhs_rs, rhs_cs),
        )
    }
}

/// The detected engine; a bf16 GEMM on a CPU without one is a caller's bug (see
/// [`available`]).
fn detected() -> Engine {
    engine().expect("bf16 GEMM on a CPU without a bf16 engine (check bf16::available)")
}

/// [`gemm`] on a given engine.
///
/// # Safety
/// `engine` runs on this CPU; the strided extents lie inside the slices (checked).
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_on(
    engine: Engine,
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    dst_rs: usize,
    accumulate: bool,
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: Rhs,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!((m - 1) * dst_rs + n <= dst.len());
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                dst[r * dst_rs..r * dst_rs + n].fill(0.0);
            }
        }
        return;
    }
    assert!((m - 1) * lhs_rs + (k - 1) * lhs_cs < lhs.len());
    match rhs {
        Rhs::Strided(b, rs, cs) => assert!((k - 1) * rs + (n - 1) * cs < b.len()),
        Rhs::Packed(pb) => assert_eq!(pb.dims(), (k, n)),
    }
    #[cfg(target_arch = "x86_64")]
    {
        BUFFERS.with(|b| {
            let (ap, bp) = &mut *b.borrow_mut();
            let kp = k.div_ceil(2);
            let nslabs = n.div_ceil(16);
            if engine == Engine::Amx {
                // SAFETY: the AMX engine was detected (and the process allowed to use it).
                unsafe { amx_config() };
            }
            for (bi, p0) in (0..kp).step_by(KCP).enumerate() {
                let pc = KCP.min(kp - p0);
                let stride = pc.next_multiple_of(16);
                let b_block: &[u32] = match rhs {
                    Rhs::Packed(pb) => &pb.data[pb.offsets[bi]..pb.offsets[bi + 1]],
                    Rhs::Strided(rhs, rs, cs) => {
                        // SAFETY: AVX-512 F is part of either engine; extents asserted.
                        unsafe { pack_b(bp, rhs, rs, cs, k, n, p0, pc, stride) };
                        &bp[..nslabs * stride * 16]
                    }
                };
                let load_c = accumulate || p0 > 0;
                for r0 in (0..m).step_by(MC) {
                    let mc = MC.min(m - r0);
                    // SAFETY: as above.
                    unsafe {
                        pack_a(ap, lhs, lhs_rs, lhs_cs, k, r0, mc, p0, pc, stride);
                    }
                    let c = &mut dst[r0 * dst_rs..];
                    let block = Block {
                        a: ap,
                        b: b_block,
                        pairs: pc,
                        stride,
                        rows: mc,
                        cols: n,
                        slabs: nslabs,
                    };
                    // SAFETY: the engine's features were detected; `c` holds `mc` rows of `n`
                    // at row stride `dst_rs` (asserted extents).
                    unsafe {
                        match engine {
                            Engine::Amx => amx_block(&block, c, dst_rs, load_c),
                            Engine::Avx512 => avx512_block(&block, c, dst_rs, load_c),
                        }
                    }
                }
            }
            if engine == Engine::Amx {
                // SAFETY: as above; returns the tile state to its initial (empty) state.
                unsafe { std::arch::asm!("tilerelease", options(nostack, nomem)) };
            }
        });
    }
}

/// The right-hand side of a bf16 GEMM: strided `f32` (packed per call) or packed once.
#[derive(Clone, Copy)]
enum Rhs<'a> {
    Strided(&'a [f32], usize, usize),
    Packed(&'a PackedB),
}

/// A right-hand side `B` (`k x n`) packed once for many [`gemm_packed`] calls (a layer's
/// weights, reused by every row tile). Invariant: `offsets` has one entry per `KCP`-pair block
/// of `k` plus the end, each block `ceil(n / 16)` slabs of `stride` pairs.
pub struct PackedB {
    k: usize,
    n: usize,
    data: Vec<u32>,
    offsets: Vec<usize>,
}

impl PackedB {
    /// Packs `rhs` (`k x n`, row / column strides) for [`gemm_packed`]; `None` where this CPU
    /// has no bf16 engine.
    pub fn new(rhs: &[f32], (rs, cs): (usize, usize), k: usize, n: usize) -> Option<Self> {
        engine()?;
        if k > 0 && n > 0 {
            assert!((k - 1) * rs + (n - 1) * cs < rhs.len());
        }
        let mut data = Vec::new();
        let mut offsets = vec![0];
        #[cfg(target_arch = "x86_64")]
        {
            let kp = k.div_ceil(2);
            let mut buf = Vec::new();
            for p0 in (0..kp).step_by(KCP) {
                let pc = KCP.min(kp - p0);
                let stride = pc.next_multiple_of(16);
                // SAFETY: an engine was detected (AVX-512 F); extents asserted above.
                unsafe { pack_b(&mut buf, rhs, rs, cs, k, n, p0, pc, stride) };
                data.extend_from_slice(&buf[..n.div_ceil(16) * stride * 16]);
                offsets.push(data.len());
            }
        }
        Some(Self {
            k,
            n,
            data,
            offsets,
        })
    }

    /// `(k, n)`.
    pub fn dims(&self) -> (usize, usize) {
        (self.k, self.n)
    }
}

/// [`gemm()`] with a right-hand side packed by [`PackedB::new`]: `dst[m, n] (+)= lhs[m, k] B`.
///
/// # Safety
/// The strided extents of `lhs` and `dst` must lie inside the slices (checked).
pub unsafe fn gemm_packed(
    m: usize,
    dst: &mut [f32],
    dst_rs: usize,
    accumulate: bool,
    lhs: &[f32],
    lhs_strides: (usize, usize),
    b: &PackedB,
) {
    let (k, n) = b.dims();
    // SAFETY: the caller's extents (checked inside).
    unsafe {
        gemm_on(
            detected(),
            m,
            n,
            k,
            dst,
            dst_rs,
            accumulate,
            lhs,
            lhs_strides,
            Rhs::Packed(b),
        )
    }
}

/// One packed block: `rows` rows of `A` (padded to [`ROWS_PAD`]) by `pairs` pairs (padded to
/// `stride`), times `slabs` 16-column slabs of `B`, into `rows x cols` of `C`.
struct Block<'a> {
    a: &'a [u32],
    b: &'a [u32],
    pairs: usize,
    stride: usize,
    rows: usize,
    cols: usize,
    slabs: usize,
}

/// `C[rows, cols] (+)= A B` for a [`Block`] with the AVX-512 micro-kernel.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn avx512_block(blk: &Block, c: &mut [f32], c_rs: usize, load_c: bool) {
    let panels = blk.rows.div_ceil(MR);
    let mut s = 0;
    while s < blk.slabs {
        let v = if blk.slabs - s >= 2 { 2 } else { 1 };
        let c0 = s * 16;
        let cols = (16 * v).min(blk.cols - c0);
        for pi in 0..panels {
            let rows = MR.min(blk.rows - pi * MR);
            let a = &blk.a[pi * MR * blk.stride..];
            let b = &blk.b[s * 16 * blk.stride..];
            let c = &mut c[pi * MR * c_rs + c0..];
            // SAFETY: `a` holds MR rows of `stride` pairs, `b` v slabs; `c` rows x cols at
            // row stride c_rs (the caller's extents).
            unsafe {
                if v == 2 {
                    micro::<2>(a, b, blk.pairs, blk.stride, c, c_rs, rows, cols, load_c);
                } else {
                    micro::<1>(a, b, blk.pairs, blk.stride, c, c_rs, rows, cols, load_c);
                }
            }
        }
        s += v;
    }
}

/// The AMX tile configuration: palette 1, all eight tiles 16 rows of 64 bytes.
#[cfg(target_arch = "x86_64")]
#[repr(C, align(64))]
struct TileConfig {
    palette: u8,
    start_row: u8,
    reserved: [u8; 14],
    colsb: [u16; 16],
    rows: [u8; 16],
}

/// Loads [`TileConfig`] on this thread.
///
/// # Safety
/// AMX must be usable ([`Engine::Amx`]).
#[cfg(target_arch = "x86_64")]
unsafe fn amx_config() {
    let mut cfg = TileConfig {
        palette: 1,
        start_row: 0,
        reserved: [0; 14],
        colsb: [0; 16],
        rows: [0; 16],
    };
    for t in 0..8 {
        cfg.colsb[t] = 64;
        cfg.rows[t] = 16;
    }
    // SAFETY: a valid 64-byte configuration (caller: AMX usable).
    unsafe {
        std::arch::asm!("ldtilecfg [{}]", in(reg) &cfg as *const TileConfig, options(nostack, readonly));
    }
}

/// `C[rows, cols] (+)= A B` for a [`Block`] with AMX tiles: 32 x 32 blocks of `C` in tiles 0-3,
/// `A` tiles 4-5 and `B` tiles 6-7 per 16 pairs.
///
/// # Safety
/// [`amx_config`] ran on this thread; `c` holds the block's rows at row stride `c_rs`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn amx_block(blk: &Block, c: &mut [f32], c_rs: usize, load_c: bool) {
    use std::arch::asm;
    let a_stride = blk.stride * 4;
    let rows_p = blk.rows.next_multiple_of(16);
    let mut out = [0.0f32; 256];
    for r0 in (0..rows_p).step_by(32) {
        let two_r = r0 + 16 < rows_p;
        for s0 in (0..blk.slabs).step_by(2) {
            let two_s = s0 + 1 < blk.slabs;
            // SAFETY (this block): tiles as configured; every load reads 16 rows of 64 bytes
            // inside the packed buffers (rows padded to ROWS_PAD >= r0 + 32 where two_r, pairs
            // padded to `stride`, a multiple of 16; slabs s0 (+ 1) exist).
            unsafe {
                asm!(
                    "tilezero tmm0",
                    "tilezero tmm1",
                    "tilezero tmm2",
                    "tilezero tmm3",
                    options(nostack, nomem)
                );
                for p in (0..blk.stride).step_by(16) {
                    let a0 = blk.a.as_ptr().add(r0 * blk.stride + p);
                    let b0 = blk.b.as_ptr().add((s0 * blk.stride + p) * 16);
                    asm!("tileloadd tmm4, [{p} + {s}*1]", p = in(reg) a0, s = in(reg) a_stride, options(nostack, readonly));
                    asm!("tileloadd tmm6, [{p} + {s}*1]", p = in(reg) b0, s = in(reg) 64usize, options(nostack, readonly));
                    asm!("tdpbf16ps tmm0, tmm4, tmm6", options(nostack, nomem));
                    if two_s {
                        let b1 = b0.add(blk.stride * 16);
                        asm!("tileloadd tmm7, [{p} + {s}*1]", p = in(reg) b1, s = in(reg) 64usize, options(nostack, readonly));
                        asm!("tdpbf16ps tmm1, tmm4, tmm7", options(nostack, nomem));
                    }
                    if two_r {
                        let a1 = a0.add(16 * blk.stride);
                        asm!("tileloadd tmm5, [{p} + {s}*1]", p = in(reg) a1, s = in(reg) a_stride, options(nostack, readonly));
                        asm!("tdpbf16ps tmm2, tmm5, tmm6", options(nostack, nomem));
                        if two_s {
                            asm!("tdpbf16ps tmm3, tmm5, tmm7", options(nostack, nomem));
                        }
                    }
                }
            }
            for (t, (dr, ds)) in [(0usize, 0usize), (0, 1), (1, 0), (1, 1)]
                .into_iter()
                .enumerate()
            {
                if (dr == 1 && !two_r) || (ds == 1 && !two_s) {
                    continue;
                }
                // SAFETY: `out` is 16 rows of 64 bytes.
                unsafe {
                    let o = out.as_mut_ptr();
                    match t {
                        0 => {
                            asm!("tilestored [{p} + {s}*1], tmm0", p = in(reg) o, s = in(reg) 64usize, options(nostack))
                        }
                        1 => {
                            asm!("tilestored [{p} + {s}*1], tmm1", p = in(reg) o, s = in(reg) 64usize, options(nostack))
                        }
                        2 => {
                            asm!("tilestored [{p} + {s}*1], tmm2", p = in(reg) o, s = in(reg) 64usize, options(nostack))
                        }
                        _ => {
                            asm!("tilestored [{p} + {s}*1], tmm3", p = in(reg) o, s = in(reg) 64usize, options(nostack))
                        }
                    }
                }
                let row0 = r0 + 16 * dr;
                let col0 = (s0 + ds) * 16;
                if row0 >= blk.rows || col0 >= blk.cols {
                    continue;
                }
                let w = 16.min(blk.cols - col0);
                for (i, src) in out.chunks_exact(16).enumerate().take(blk.rows - row0) {
                    let d = &mut c[(row0 + i) * c_rs + col0..][..w];
                    if load_c {
                        d.iter_mut().zip(src).for_each(|(x, y)| *x += y);
                    } else {
                        d.copy_from_slice(&src[..w]);
                    }
                }
            }
        }
    }
}

/// Lane `j`: `bf16(lo[j]) | bf16(hi[j]) << 16` (ties to even; NaN not preserved, never fed).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
fn pair16(lo: __m512, hi: __m512) -> __m512i {
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn bits(x: __m512) -> __m512i {
        let b = _mm512_castps_si512(x);
        let lsb = _mm512_and_si512(_mm512_srli_epi32::<16>(b), _mm512_set1_epi32(1));
        let r = _mm512_add_epi32(b, _mm512_add_epi32(_mm512_set1_epi32(0x7FFF), lsb));
        _mm512_srli_epi32::<16>(r)
    }
    _mm512_or_si512(bits(lo), _mm512_slli_epi32::<16>(bits(hi)))
}

/// A pair of `f32` as one 32-bit bf16 pair.
#[inline]
fn pair(lo: f32, hi: f32) -> u32 {
    u32::from(to_bf16(lo)) | (u32::from(to_bf16(hi)) << 16)
}

/// Packs pairs `p0 .. p0 + pc` of `B` (`k x n`, strides `rs`, `cs`) into 16-column slabs of
/// `stride` pairs: `bp[(slab * stride + p) * 16 + j]`, zeros past `pc`, `k` and `n`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn pack_b(
    bp: &mut Vec<u32>,
    b: &[f32],
    rs: usize,
    cs: usize,
    k: usize,
    n: usize,
    p0: usize,
    pc: usize,
    stride: usize,
) {
    let nslabs = n.div_ceil(16);
    if bp.len() < nslabs * stride * 16 {
        bp.resize(nslabs * stride * 16, 0);
    }
    // Every (slab, pair < pc) lane is written below; zero the pairs past pc.
    for s in 0..nslabs {
        bp[(s * stride + pc) * 16..(s + 1) * stride * 16].fill(0);
    }
    let at = |kk: usize, j: usize| -> f32 {
        if kk < k && j < n {
            b[kk * rs + j * cs]
        } else {
            0.0
        }
    };
    for s in 0..nslabs {
        let j0 = s * 16;
        for p in 0..pc {
            let (k0, k1) = (2 * (p0 + p), 2 * (p0 + p) + 1);
            let out = &mut bp[(s * stride + p) * 16..(s * stride + p + 1) * 16];
            if cs == 1 && j0 + 16 <= n && k1 < k {
                // SAFETY: columns j0..j0+16 of rows k0, k1 are inside `b` (k1 < k, j0+16 <= n).
                unsafe {
                    let lo = _mm512_loadu_ps(b.as_ptr().add(k0 * rs + j0));
                    let hi = _mm512_loadu_ps(b.as_ptr().add(k1 * rs + j0));
                    _mm512_storeu_si512(out.as_mut_ptr().cast(), pair16(lo, hi));
                }
            } else {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = pair(at(k0, j0 + j), at(k1, j0 + j));
                }
            }
        }
    }
}

/// Packs rows `r0 .. r0 + mc` and pairs `p0 .. p0 + pc` of `A` (`m x k`, strides `rs`, `cs`)
/// into rows of `stride` pairs: `ap[r * stride + p]`, zero rows up to a multiple of
/// [`ROWS_PAD`] and zero pairs past `pc`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn pack_a(
    ap: &mut Vec<u32>,
    a: &[f32],
    rs: usize,
    cs: usize,
    k: usize,
    r0: usize,
    mc: usize,
    p0: usize,
    pc: usize,
    stride: usize,
) {
    let rows_p = mc.next_multiple_of(ROWS_PAD);
    if ap.len() < rows_p * stride {
        ap.resize(rows_p * stride, 0);
    }
    // Every (row < mc, pair < pc) is written below; zero the rest of the block.
    if pc < stride {
        for r in 0..mc {
            ap[r * stride + pc..(r + 1) * stride].fill(0);
        }
    }
    ap[mc * stride..rows_p * stride].fill(0);
    let k_lo = 2 * p0;
    let k_hi = (2 * (p0 + pc)).min(k);
    if cs == 1 {
        // Rows contiguous along k: 32 values -> 16 pairs, in order.
        let idx_lo = _mm512_set_epi32(30, 28, 26, 24, 22, 20, 18, 16, 14, 12, 10, 8, 6, 4, 2, 0);
        let idx_hi = _mm512_set_epi32(31, 29, 27, 25, 23, 21, 19, 17, 15, 13, 11, 9, 7, 5, 3, 1);
        for r in 0..mc {
            let row = &a[(r0 + r) * rs..];
            let out = &mut ap[r * stride..r * stride + pc];
            let mut kk = k_lo;
            let mut p = 0;
            while kk + 32 <= k_hi {
                // SAFETY: kk + 32 <= k_hi <= k, so the 32 values are inside the row; p + 16
                // <= pc.
                unsafe {
                    let x0 = _mm512_loadu_ps(row.as_ptr().add(kk));
                    let x1 = _mm512_loadu_ps(row.as_ptr().add(kk + 16));
                    let ev = _mm512_permutex2var_ps(x0, idx_lo, x1);
                    let od = _mm512_permutex2var_ps(x0, idx_hi, x1);
                    _mm512_storeu_si512(out.as_mut_ptr().add(p).cast(), pair16(ev, od));
                }
                kk += 32;
                p += 16;
            }
            while kk < k_hi {
                let hi = if kk + 1 < k { row[kk + 1] } else { 0.0 };
                out[p] = pair(row[kk], hi);
                kk += 2;
                p += 1;
            }
        }
    } else if rs == 1 {
        // Columns contiguous along m (A^T row-major): 16 rows at a time per pair.
        for p in 0..pc {
            let (k0, k1) = (2 * (p0 + p), 2 * (p0 + p) + 1);
            let mut r = 0;
            while r + 16 <= mc && k1 < k {
                // SAFETY: rows r0+r .. r0+r+16 (< m) of columns k0, k1 (< k).
                let v = unsafe {
                    let lo = _mm512_loadu_ps(a.as_ptr().add(k0 * cs + r0 + r));
                    let hi = _mm512_loadu_ps(a.as_ptr().add(k1 * cs + r0 + r));
                    pair16(lo, hi)
                };
                let mut lanes = [0u32; 16];
                // SAFETY: 16 u32 lanes into a 16-element array.
                unsafe { _mm512_storeu_si512(lanes.as_mut_ptr().cast(), v) };
                for (i, l) in lanes.iter().enumerate() {
                    ap[(r + i) * stride + p] = *l;
                }
                r += 16;
            }
            while r < mc {
                let hi = if k1 < k { a[(r0 + r) + k1 * cs] } else { 0.0 };
                ap[r * stride + p] = pair(a[(r0 + r) + k0 * cs], hi);
                r += 1;
            }
        }
    } else {
        for r in 0..mc {
            for p in 0..pc {
                let (k0, k1) = (2 * (p0 + p), 2 * (p0 + p) + 1);
                let hi = if k1 < k {
                    a[(r0 + r) * rs + k1 * cs]
                } else {
                    0.0
                };
                ap[r * stride + p] = pair(a[(r0 + r) * rs + k0 * cs], hi);
            }
        }
    }
}

/// `C[rows, cols] (+)= A_panel B_slabs` over `pc` pairs (`A` rows and `B` slabs `stride` pairs
/// apart); `V` slabs of 16 columns.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
#[allow(clippy::too_many_arguments)]
unsafe fn micro<const V: usize>(
    a: &[u32],
    b: &[u32],
    pc: usize,
    stride: usize,
    c: &mut [f32],
    c_rs: usize,
    rows: usize,
    cols: usize,
    load_c: bool,
) {
    debug_assert!(a.len() >= (MR - 1) * stride + pc && b.len() >= ((V - 1) * stride + pc) * 16);
    let mut acc = [[_mm512_setzero_ps(); V]; MR];
    let ap = a.as_ptr();
    let bp = b.as_ptr();
    for p in 0..pc {
        let mut bv = [_mm512_setzero_si512(); V];
        for (v, slot) in bv.iter_mut().enumerate() {
            // SAFETY: slab v, pair p: 16 u32 inside `b` (debug-asserted length).
            *slot = unsafe { _mm512_loadu_si512(bp.add((v * stride + p) * 16).cast()) };
        }
        for (r, row) in acc.iter_mut().enumerate() {
            // SAFETY: row r, pair p inside `a`.
            let ar = _mm512_set1_epi32(unsafe { *ap.add(r * stride + p) } as i32);
            for (v, slot) in row.iter_mut().enumerate() {
                // SAFETY: the two types are the same 512 bits (32 bf16 values).
                let (x, y) = unsafe {
                    (
                        std::mem::transmute::<__m512i, __m512bh>(ar),
                        std::mem::transmute::<__m512i, __m512bh>(bv[v]),
                    )
                };
                *slot = _mm512_dpbf16_ps(*slot, x, y);
            }
        }
    }
    for (r, row) in acc.iter().enumerate().take(rows) {
        for (v, val) in row.iter().enumerate() {
            let c0 = v * 16;
            if c0 >= cols {
                break;
            }
            let w = (cols - c0).min(16);
            let mask: __mmask16 = if w == 16 { 0xFFFF } else { (1u16 << w) - 1 };
            // SAFETY: row r < rows, columns c0 .. c0 + w < cols: inside `c` (caller).
            unsafe {
                let ptr = c.as_mut_ptr().add(r * c_rs + c0);
                let out = if load_c {
                    _mm512_add_ps(_mm512_maskz_loadu_ps(mask, ptr), *val)
                } else {
                    *val
                };
                _mm512_mask_storeu_ps(ptr, mask, out);
            }
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::fast::testing::lcg;

    /// Packing `B` once gives the same bits as packing it per call.
    #[test]
    fn prepacked_rhs_equals_the_strided_one() {
        if !available() {
            return;
        }
        for &(m, n, k) in &[(7, 5, 3), (100, 48, 864), (33, 130, 600)] {
            let a = lcg(5, m * k);
            let b = lcg(6, k * n);
            let mut c1 = vec![0.5f32; m * n];
            let mut c2 = c1.clone();
            let pb = PackedB::new(&b, (n, 1), k, n).expect("engine detected");
            // SAFETY: a [m, k], b [k, n], c [m, n].
            unsafe {
                gemm(m, n, k, &mut c1, n, true, &a, (k, 1), &b, (n, 1));
                gemm_packed(m, &mut c2, n, true, &a, (k, 1), &pb);
            }
            assert!(c1 == c2, "{m}x{n}x{k}");
        }
    }

    #[test]
    fn rounding_is_to_nearest_even() {
        assert_eq!(round_bf16(1.0), 1.0);
        // 1 + 2^-8 is halfway between 1 and 1 + 2^-7: ties to even (1.0).
        assert_eq!(round_bf16(1.0 + 1.0 / 256.0), 1.0);
        assert_eq!(round_bf16(1.0 + 3.0 / 256.0), 1.0 + 4.0 / 256.0);
        assert_eq!(round_bf16(-2.5), -2.5);
        for x in lcg(1, 1000) {
            assert!((round_bf16(x) - x).abs() <= x.abs() / 256.0);
        }
    }

    /// The kernel equals the f64 product of the bf16-rounded inputs up to f32 summation error,
    /// for every stride kind, odd sizes, padding on every side, and accumulation.
    #[test]
    fn gemm_equals_the_product_of_the_rounded_inputs() {
        let mut engines = vec![];
        if is_x86_feature_detected!("avx512f") && amx_usable() {
            engines.push(Engine::Amx);
        }
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512bf16") {
            engines.push(Engine::Avx512);
        }
        if engines.is_empty() {
            eprintln!("no bf16 engine on this CPU: bf16 kernel not tested");
            return;
        }
        for engine in engines {
            for &(m, n, k) in &[
                (1, 1, 1),
                (3, 4, 0),
                (13, 17, 3),
                (12, 32, 64),
                (97, 48, 515),
                (200, 128, 40),
                (5, 200, 1030),
            ] {
                let a = lcg(m as u64 * 7 + k as u64, m * k);
                let b = lcg(n as u64 * 3 + 11, k * n);
                let c0 = lcg(99, m * (n + 3));
                // (A strides, B strides): row-major A, A^T row-major, general; row-major B, B^T.
                for (sa, sb) in [
                    ((k, 1), (n, 1)),
                    ((1, m), (n, 1)),
                    ((1, m), (1, k)),
                    ((k, 1), (1, k)),
                ] {
                    for acc in [false, true] {
                        let mut c = c0.clone();
                        // SAFETY: `a` has m*k values and `b` k*n in either layout; `c` m rows of
                        // n + 3 (row stride n + 3).
                        unsafe {
                            gemm_on(
                                engine,
                                m,
                                n,
                                k,
                                &mut c,
                                n + 3,
                                acc,
                                &a,
                                sa,
                                Rhs::Strided(&b, sb.0, sb.1),
                            )
                        };
                        for i in 0..m {
                            for j in 0..n + 3 {
                                let got = c[i * (n + 3) + j];
                                if j >= n {
                                    assert_eq!(got, c0[i * (n + 3) + j], "padding touched");
                                    continue;
                                }
                                let mut want = 0.0f64;
                                let mut mag = 0.0f64;
                                for kk in 0..k {
                                    let x = f64::from(round_bf16(a[i * sa.0 + kk * sa.1]));
                                    let y = f64::from(round_bf16(b[kk * sb.0 + j * sb.1]));
                                    want += x * y;
                                    mag += (x * y).abs();
                                }
                                if acc {
                                    want += f64::from(c0[i * (n + 3) + j]);
                                    mag += f64::from(c0[i * (n + 3) + j]).abs();
                                }
                                assert!(
                                    (f64::from(got) - want).abs() <= 1e-6 * (1.0 + mag),
                                    "{engine:?} {m}x{n}x{k} {sa:?} {sb:?} acc {acc} [{i},{j}]: {got} vs {want}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
