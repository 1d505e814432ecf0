//! The one call into `gemm` (the crate burn-flex multiplies with), behind bounds
//! checked views so that the rest of the kernels stay safe code.
#![allow(unsafe_code)]

/// A read-only matrix over a slice: element (r, c) is `data[r·row_stride + c·col_stride]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct View<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

impl<'a> View<'a> {
    /// `rows × cols`, stored row after row.
    pub(crate) fn rows(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transpose, without copying.
    pub(crate) fn t(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }

    /// Whether every element lies inside `data`.
    fn fits(&self) -> bool {
        if self.rows == 0 || self.cols == 0 {
            return true;
        }
        let last = (self.rows - 1)
            .checked_mul(self.row_stride)
            .zip((self.cols - 1).checked_mul(self.col_stride))
            .and_then(|(a, b)| a.checked_add(b));
        last.is_some_and(|i| i < self.data.len())
            && isize::try_from(self.row_stride).is_ok()
            && isize::try_from(self.col_stride).is_ok()
    }
}

/// `dst = a·b` (or `dst += a·b` with `accumulate`), `dst` being `a.rows × b.cols`
/// stored row after row.
///
/// # Panics
/// When the shapes disagree or a view reaches outside its slice: a bug in the caller,
/// never a property of the data.
pub(crate) fn matmul(dst: &mut [f32], accumulate: bool, a: View<'_>, b: View<'_>) {
    let (m, k, n) = (a.rows, a.cols, b.cols);
    assert_eq!(k, b.rows, "matmul: {m}×{k} by {}×{n}", b.rows);
    assert!(
        a.fits() && b.fits(),
        "matmul: a view reaches outside its data"
    );
    let len = m.checked_mul(n).expect("matmul: m·n overflows");
    assert!(dst.len() >= len, "matmul: {} for {m}×{n}", dst.len());
    if len == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..len].fill(0.0);
        }
        return;
    }
    // SAFETY: every element gemm reads lies in `a.data` or `b.data` (checked by `fits`,
    // strides fit isize) and every element it writes in `dst[..m·n]` (row stride n,
    // column stride 1); `dst` is borrowed mutably, so it aliases neither input.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a.col_stride as isize,
            a.row_stride as isize,
            b.data.as_ptr(),
            b.col_stride as isize,
            b.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}
