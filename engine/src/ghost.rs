//! Ghost stabilisation (Coombs et al., G sections 3-4): penalise jumps in
//! the normal derivative of the displacement across the faces of the
//! elements at the edge of the material.
//!
//! Face set (G 4.2), rebuilt every step: *active* cells hold material
//! points; *boundary* cells are active cells sharing a face with an inactive
//! cell, or partly filled cells on the grid's edge; Gamma is every face between a boundary cell and
//! another active cell. For a face with unit normal `n` (out of the
//! positive cell `K+`) and the six nodes of its two cells,
//! `a_k = dN_k^+/dn - dN_k^-/dn` (the grid's bilinear functions, also under
//! GIMP) and
//!
//! `J_G = (h^3/3) sum_faces int_face a a^T dGamma (x) I_2`   (G (18), (23)),
//!
//! integrated with 2-point Gauss along each face (exact: `a` is linear
//! along the face). Stiffness `K_G = gamma_K J_G` (G (27)) with residual
//! force `f_G = K_G du`; mass `M + gamma_M J_G`. Rows of `J_G` sum to zero,
//! so rigid translations are not penalised.

use crate::grid::Grid;
pub use crate::scene::GhostCells;

/// One face of Gamma: its six nodes and the 6 x 6 scalar matrix
/// `(h^3/3) int a a^T dGamma` (to be taken `(x) I_2`).
#[derive(Clone, Debug, PartialEq)]
pub struct GhostFace {
    /// The two cells (`+` first).
    pub cells: [usize; 2],
    pub nodes: [usize; 6],
    pub j: [[f64; 6]; 6],
}

/// Ends of a face (for drawing): `((x0, y0), (x1, y1))`.
pub fn face_segment(grid: &Grid, f: &GhostFace) -> ([f64; 2], [f64; 2]) {
    let (a, b) = (f.cells[0], f.cells[1]);
    let (ia, ja) = (a % grid.nx, a / grid.nx);
    let (ib, jb) = (b % grid.nx, b / grid.nx);
    let h = grid.h;
    if ja == jb {
        // Vertical face between horizontal neighbours.
        let x = grid.origin[0] + ia.max(ib) as f64 * h;
        let y = grid.origin[1] + ja as f64 * h;
        ([x, y], [x, y + h])
    } else {
        let y = grid.origin[1] + ja.max(jb) as f64 * h;
        let x = grid.origin[0] + ia as f64 * h;
        ([x, y], [x + h, y])
    }
}

/// The ghost faces of a mapping, with `cells` deciding which cells count
/// as active.
pub fn faces_of(grid: &Grid, map: &crate::assembly::Mapping, cells: GhostCells) -> Vec<GhostFace> {
    match cells {
        GhostCells::Reached => faces(grid, &map.active_cells, &map.cell_fill),
        GhostCells::Populated => faces(grid, &map.populated_cells, &map.cell_fill),
    }
}

/// Fill fraction below which a cell on the grid's edge counts as cut by the
/// material's boundary.
const PARTLY_FILLED: f64 = 0.9;

/// The ghost faces for the active cells `active` (cell indices); `fill`
/// is each grid cell's filled fraction (see [`crate::assembly::Mapping::cell_fill`]).
pub fn faces(grid: &Grid, active: &[usize], fill: &[f64]) -> Vec<GhostFace> {
    let mut is_active = vec![false; grid.num_cells()];
    for &c in active {
        is_active[c] = true;
    }
    let neighbours = |c: usize| {
        let (i, j) = (c % grid.nx, c / grid.nx);
        let mut n = Vec::with_capacity(4);
        if i > 0 {
            n.push(c - 1);
        }
        if i + 1 < grid.nx {
            n.push(c + 1);
        }
        if j > 0 {
            n.push(c - grid.nx);
        }
        if j + 1 < grid.ny {
            n.push(c + grid.nx);
        }
        n
    };
    // A cell on the grid's edge whose other neighbours are all active is
    // still cut by the material's boundary when it is partly filled (a body
    // leaving a corner of the grid): without it, the nodes there that points
    // barely touch would be held by no face. A full cell on the edge (a body
    // supported on the grid's boundary) is not.
    let boundary: Vec<bool> = (0..grid.num_cells())
        .map(|c| {
            let n = neighbours(c);
            is_active[c] && (n.iter().any(|&n| !is_active[n]) || (n.len() < 4 && fill[c] < PARTLY_FILLED))
        })
        .collect();
    let mut out = Vec::new();
    for &c in active {
        // Each face once: look right and up only.
        let (i, j) = (c % grid.nx, c / grid.nx);
        let mut candidates = Vec::new();
        if i + 1 < grid.nx {
            candidates.push(c + 1);
        }
        if j + 1 < grid.ny {
            candidates.push(c + grid.nx);
        }
        for n in candidates {
            if is_active[n] && (boundary[c] || boundary[n]) {
                out.push(face_matrix(grid, c, n));
            }
        }
    }
    out
}

/// `J` of the face between cell `a` and its right or upper neighbour `b`.
fn face_matrix(grid: &Grid, a: usize, b: usize) -> GhostFace {
    let h = grid.h;
    let (ia, ja) = (a % grid.nx, a / grid.nx);
    let vertical = b == a + 1; // face x = const between a (left) and b (right)
                               // Six nodes: the union of the two cells' corners.
    let nodes: [usize; 6] = if vertical {
        [
            grid.node(ia, ja),
            grid.node(ia + 1, ja),
            grid.node(ia + 2, ja),
            grid.node(ia, ja + 1),
            grid.node(ia + 1, ja + 1),
            grid.node(ia + 2, ja + 1),
        ]
    } else {
        [
            grid.node(ia, ja),
            grid.node(ia + 1, ja),
            grid.node(ia, ja + 1),
            grid.node(ia + 1, ja + 1),
            grid.node(ia, ja + 2),
            grid.node(ia + 1, ja + 2),
        ]
    };
    // Along the face, s in [0, 1]; normal derivative of each cell's bilinear
    // functions on the face. Vertical face: n = +x out of `a` (left cell).
    // Left cell nodes (0,1,3,4) at local (xi, eta) = (0,0),(1,0),(0,1),(1,1);
    // on the face xi = 1: dN/dx = (+-1/h) (1 - eta or eta).
    // Right cell nodes (1,2,4,5); on its face xi = 0.
    let g = 1.0 / 3f64.sqrt();
    let mut j = [[0.0; 6]; 6];
    for s in [0.5 * (1.0 - g), 0.5 * (1.0 + g)] {
        let mut av = [0.0; 6];
        // `+` cell (a): derivative along n at its far face; `-` cell (b): at its near face.
        // For both orientations the pattern is the same with nodes ordered
        // [near row/col of a, shared, far of b] x [two lines along the face].
        let (lo, hi) = (1.0 - s, s);
        // Cell a (+): nodes 0,1 (line 0) and 3,4 (line 1): d/dn = (N at shared - N at near)/h.
        av[0] -= lo / h;
        av[1] += lo / h;
        av[3] -= hi / h;
        av[4] += hi / h;
        // Cell b (-): nodes 1,2 and 4,5: subtract its d/dn.
        av[1] -= -lo / h;
        av[2] -= lo / h;
        av[4] -= -hi / h;
        av[5] -= hi / h;
        // Weight: Gauss weight 1/2 on [0, 1] times face length h, times h^3/3.
        let w = 0.5 * h * h.powi(3) / 3.0;
        for r in 0..6 {
            for c in 0..6 {
                j[r][c] += w * av[r] * av[c];
            }
        }
    }
    // For horizontal faces the node numbering above maps (line, across)
    // the same way: nodes [0,1] are the near row of a, [2,3] the shared row,
    // [4,5] the far row of b, so reorder into that layout.
    let nodes = if vertical {
        nodes
    } else {
        // Layout wanted: [near0, shared0, far0, near1, shared1, far1] with
        // lines running along x: near row = (ia, ja), (ia+1, ja); etc.
        [nodes[0], nodes[2], nodes[4], nodes[1], nodes[3], nodes[5]]
    };
    GhostFace {
        cells: [a, b],
        nodes,
        j,
    }
}

/// The ghost force `f_G = gamma (J_G (x) I_2) d` at every grid node for a
/// step whose nodal increment is `d` (N per unit thickness); empty when
/// there are no faces.
pub fn force(faces: &[GhostFace], gamma: f64, d: &[[f64; 2]]) -> Vec<[f64; 2]> {
    if faces.is_empty() || gamma == 0.0 {
        return Vec::new();
    }
    let mut f = vec![[0.0; 2]; d.len()];
    for face in faces {
        for r in 0..6 {
            for c in 0..2 {
                f[face.nodes[r]][c] += gamma * (0..6).map(|k| face.j[r][k] * d[face.nodes[k]][c]).sum::<f64>();
            }
        }
    }
    f
}

/// The work the ghost force does over a step with nodal increment `d`,
/// trapezoidal like the loads' work: `1/2 (f_G^start + f_G^end) . d`.
/// The grid is reset every step, so the penalty acts on each step's
/// increment alone and its force at the end of a step (`end`, from
/// [`force`]) is not carried by the stresses: the next step starts with it
/// as out-of-balance (`start`, the previous step's `end`). Empty vectors
/// count as zero.
pub fn step_work(start: &[[f64; 2]], end: &[[f64; 2]], d: &[[f64; 2]]) -> f64 {
    let dot = |f: &[[f64; 2]]| f.iter().zip(d).map(|(f, u)| f[0] * u[0] + f[1] * u[1]).sum::<f64>();
    0.5 * (dot(start) + dot(end))
}

impl GhostFace {
    /// `gamma (J (x) I_2)` as a row-major 12 x 12 matrix over the face's
    /// nodes `[x0, y0, x1, y1, ...]`.
    pub fn stiffness(&self, gamma: f64, out: &mut Vec<f64>) {
        out.clear();
        out.resize(144, 0.0);
        for r in 0..6 {
            for c in 0..6 {
                let v = gamma * self.j[r][c];
                out[(2 * r) * 12 + 2 * c] = v;
                out[(2 * r + 1) * 12 + 2 * c + 1] = v;
            }
        }
    }
}
