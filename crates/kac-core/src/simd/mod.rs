//! Vectors of doubles for the hand-written numerical kernels (the eigensolver's block solve and basis products,
//! the sparse block product): one kernel body, written against `F64s` (crate-private, like the kernels: callers
//! reach them through safe wrappers that check sizes and strides), compiled once per instruction set — AVX2 + FMA
//! (four lanes) and AVX-512F (eight lanes) — and chosen at run time by [`Isa::detect`], as faer chooses its own
//! kernels.
//!
//! The pattern: a kernel is an `#[inline(always)]` generic function over `S: F64s`; a thin wrapper per instruction
//! set, compiled with `#[target_feature]`, instantiates it with `__m256d` or `__m512d`, so the whole body (the
//! trait's methods included, themselves compiled for the same features) is inlined into code built for that set.

/// The widest vector instruction set the kernels have for this CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// AVX-512F: eight doubles per register, 32 registers.
    Avx512,
    /// AVX2 with FMA: four doubles per register, 16 registers.
    Avx2,
    /// Neither: the portable code paths.
    Scalar,
}

impl Isa {
    /// The widest set this CPU supports (the standard library caches the detection).
    pub fn detect() -> Isa {
        [Isa::Avx512, Isa::Avx2].into_iter().find(|i| i.supported()).unwrap_or(Isa::Scalar)
    }

    /// Whether this CPU can run the set's kernels.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            match self {
                // Every AVX-512 CPU has AVX2 and FMA too; the narrow widths fall back to those kernels.
                Isa::Avx512 => std::is_x86_feature_detected!("avx512f") && Isa::Avx2.supported(),
                Isa::Avx2 => std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma"),
                Isa::Scalar => true,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Isa::Scalar
        }
    }

    /// Every set this CPU can run, widest first (the tests run each kernel on all of them).
    pub fn available() -> Vec<Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Scalar].into_iter().filter(|i| i.supported()).collect()
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use registers::F64s;

#[cfg(target_arch = "x86_64")]
pub(crate) mod supernodal;

#[cfg(target_arch = "x86_64")]
mod registers {
    use std::arch::x86_64::*;

    /// A register of `LANES` doubles and the operations the kernels use. Every method may only run on a CPU with the
    /// register's instruction set, from code compiled for it. Crate-private: the kernels behind the safe wrappers
    /// (`Cholesky::solve_in_place_with`, `basis_products::gram_with`, `update_with`) are its only users.
    pub(crate) trait F64s: Copy {
        /// Doubles per register.
        const LANES: usize;
        /// # Safety
        /// The CPU has the register's instruction set.
        unsafe fn zero() -> Self;
        /// `*p` in every lane.
        /// # Safety
        /// As [`F64s::zero`]; `p` is valid for one read.
        unsafe fn splat(p: *const f64) -> Self;
        /// # Safety
        /// As [`F64s::zero`]; `p` is valid for `LANES` reads (no alignment needed).
        unsafe fn load(p: *const f64) -> Self;
        /// # Safety
        /// As [`F64s::zero`]; `p` is valid for `LANES` writes (no alignment needed).
        unsafe fn store(self, p: *mut f64);
        /// self · a + c, fused.
        /// # Safety
        /// As [`F64s::zero`].
        unsafe fn mul_add(self, a: Self, c: Self) -> Self;
        /// c − self · a, fused.
        /// # Safety
        /// As [`F64s::zero`].
        unsafe fn neg_mul_add(self, a: Self, c: Self) -> Self;
        /// # Safety
        /// As [`F64s::zero`].
        unsafe fn mul(self, a: Self) -> Self;
        /// # Safety
        /// As [`F64s::zero`].
        unsafe fn sub(self, a: Self) -> Self;
    }

    impl F64s for __m256d {
        const LANES: usize = 4;
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn zero() -> Self {
            _mm256_setzero_pd()
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn splat(p: *const f64) -> Self {
            // SAFETY: `p` is valid for one read (this method's contract).
            _mm256_broadcast_sd(unsafe { &*p })
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn load(p: *const f64) -> Self {
            // SAFETY: `p` is valid for four reads (this method's contract); `loadu` needs no alignment.
            unsafe { _mm256_loadu_pd(p) }
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn store(self, p: *mut f64) {
            // SAFETY: `p` is valid for four writes (this method's contract); `storeu` needs no alignment.
            unsafe { _mm256_storeu_pd(p, self) }
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn mul_add(self, a: Self, c: Self) -> Self {
            _mm256_fmadd_pd(self, a, c)
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn neg_mul_add(self, a: Self, c: Self) -> Self {
            _mm256_fnmadd_pd(self, a, c)
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn mul(self, a: Self) -> Self {
            _mm256_mul_pd(self, a)
        }
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn sub(self, a: Self) -> Self {
            _mm256_sub_pd(self, a)
        }
    }

    impl F64s for __m512d {
        const LANES: usize = 8;
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn zero() -> Self {
            _mm512_setzero_pd()
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn splat(p: *const f64) -> Self {
            // SAFETY: `p` is valid for one read (this method's contract).
            _mm512_set1_pd(unsafe { *p })
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn load(p: *const f64) -> Self {
            // SAFETY: `p` is valid for eight reads (this method's contract); `loadu` needs no alignment.
            unsafe { _mm512_loadu_pd(p) }
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn store(self, p: *mut f64) {
            // SAFETY: `p` is valid for eight writes (this method's contract); `storeu` needs no alignment.
            unsafe { _mm512_storeu_pd(p, self) }
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn mul_add(self, a: Self, c: Self) -> Self {
            _mm512_fmadd_pd(self, a, c)
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn neg_mul_add(self, a: Self, c: Self) -> Self {
            _mm512_fnmadd_pd(self, a, c)
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn mul(self, a: Self) -> Self {
            _mm512_mul_pd(self, a)
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn sub(self, a: Self) -> Self {
            _mm512_sub_pd(self, a)
        }
    }
}
