//! The background grid: a regular mesh of square bilinear (Q4) cells.
//!
//! Nodes are numbered row by row, `n = j (nx + 1) + i`, cells likewise
//! `e = j nx + i`. Positions are in metres (or the scene's length unit).

/// A regular grid of `nx` x `ny` square cells of size `h` with its lower-left
/// corner at `origin`.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    pub origin: [f64; 2],
    pub h: f64,
    pub nx: usize,
    pub ny: usize,
}

impl Grid {
    pub fn num_nodes(&self) -> usize {
        (self.nx + 1) * (self.ny + 1)
    }

    pub fn num_cells(&self) -> usize {
        self.nx * self.ny
    }

    /// Node number of node column `i`, row `j`.
    pub fn node(&self, i: usize, j: usize) -> usize {
        j * (self.nx + 1) + i
    }

    /// Column and row of node `n`.
    pub fn node_ij(&self, n: usize) -> (usize, usize) {
        (n % (self.nx + 1), n / (self.nx + 1))
    }

    /// Position of node `n`.
    pub fn node_position(&self, n: usize) -> [f64; 2] {
        let (i, j) = self.node_ij(n);
        [self.origin[0] + i as f64 * self.h, self.origin[1] + j as f64 * self.h]
    }

    /// Upper-right corner of the grid.
    pub fn max(&self) -> [f64; 2] {
        [
            self.origin[0] + self.nx as f64 * self.h,
            self.origin[1] + self.ny as f64 * self.h,
        ]
    }

    /// Cell `(i, j)` containing `x`, clamped to the grid (a point on the
    /// upper or right edge belongs to the last cell). `None` when `x` is
    /// outside the grid by more than round-off.
    pub fn cell_of(&self, x: [f64; 2]) -> Option<(usize, usize)> {
        let tol = 1e-12 * self.h;
        let mut ij = [0usize; 2];
        let n = [self.nx, self.ny];
        for d in 0..2 {
            let s = (x[d] - self.origin[d]) / self.h;
            if !s.is_finite() || s < -tol || s > n[d] as f64 + tol {
                return None;
            }
            ij[d] = (s.floor().max(0.0) as usize).min(n[d] - 1);
        }
        Some((ij[0], ij[1]))
    }

    /// Lower-left corner of cell `(i, j)`.
    pub fn cell_min(&self, i: usize, j: usize) -> [f64; 2] {
        [self.origin[0] + i as f64 * self.h, self.origin[1] + j as f64 * self.h]
    }

    /// The four nodes of cell `(i, j)`, counter-clockwise from lower left.
    pub fn cell_nodes(&self, i: usize, j: usize) -> [usize; 4] {
        [
            self.node(i, j),
            self.node(i + 1, j),
            self.node(i + 1, j + 1),
            self.node(i, j + 1),
        ]
    }

    /// Index of the grid line `x_d = c` (`d = 0` vertical lines, `d = 1`
    /// horizontal), if `c` lies on one to within `1e-9 h`.
    pub fn line_index(&self, d: usize, c: f64) -> Option<usize> {
        let s = (c - self.origin[d]) / self.h;
        let k = s.round();
        let n = if d == 0 { self.nx } else { self.ny };
        if (s - k).abs() < 1e-9 && k >= 0.0 && k <= n as f64 {
            Some(k as usize)
        } else {
            None
        }
    }
}
