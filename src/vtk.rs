//! A ParaView time series of a run: VTK XML files written with the
//! `vtkio` crate, one file per kind and step, and a `.pvd` collection per
//! kind that lists them with their time so ParaView plays them as a series.
//!
//! Layout of the folder (`mpmlab run SCENE --vtk DIR`):
//!
//! | file | VTK type | what |
//! |---|---|---|
//! | `points.pvd`, `points/<step>.vtu` | UnstructuredGrid (one vertex cell per point) | the material points at their current positions (z = 0) with every per-point value below |
//! | `grid.pvd`, `grid/<step>.vtr` | RectilinearGrid | the background grid; cell data `active` (1: the cell holds points after the step) |
//! | `boundaries.pvd`, `boundaries/<step>.vtp` | PolyData lines | the B-spline boundaries through their current points, 16 samples per segment; cell data `boundary` (index in the scene's `[[boundary]]` list) and `traction` (1: carries a traction) |
//! | `ibm.pvd`, `ibm/<step>.vtp` | PolyData lines | the implicit (IBM) Dirichlet boundaries at their current position; cell data `boundary` (index in the scene's `[[ibm]]` list) |
//!
//! `boundaries` and `ibm` exist only when the scene has such boundaries.
//! `<step>` is the load step, six digits (`000000` is the initial state).
//! A collection's `timestep` is the load factor for quasi-static analyses
//! and the simulated time (s) for explicit dynamics.
//!
//! Per-point data of `points/<step>.vtu`: every [`Field`] under its key
//! (`sigma_xx`, `sigma_yy`, `sigma_xy` in Pa, `displacement_magnitude` in
//! m, `plastic_strain`, `speed` in m/s, `error`; active scalars
//! `sigma_yy`); vectors `displacement` (m) and `velocity` (m/s) with
//! z = 0; the tensor `stress` (Pa, 9 components, row-major) with the
//! out-of-plane `s_zz` as the engine knows it (plane strain linear
//! elasticity: `nu (s_xx + s_yy)`, plane stress: 0; finite deformation and
//! explicit dynamics: the stored Kirchhoff-based `s_zz`); `volume` (m^3 per
//! unit thickness), `mass` (kg per unit thickness), `body` (index in the
//! scene's `[[body]]` list) and `yielding` (1: the last step yielded).
//! Arrays are little-endian Float64 (Int32, UInt8 for indices and flags),
//! base64 inline; ParaView, VTK's own readers and meshio read them.
//!
//! Steps are written at a cadence (every step by default, `--vtk-every N`),
//! plus the initial state, the last step, and the last good state of a run
//! that fails or stops. A state with a non-finite value is never written
//! (it is counted and named in the summary instead). Each `.pvd` is
//! complete after every step written, so an interrupted run leaves a
//! readable series.
//!
//! An observer of the runner ([`crate::runner::Observer`]); the engine
//! knows nothing of this module.

use crate::field::Field;
use crate::runner::Observer;
use crate::scene::AnalysisKind;
use crate::simulation::{Simulation, StepFailure, StepReport};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use vtkio::model::{
    Attribute, Attributes, ByteOrder, CellType, Cells, Coordinates, DataSet, Extent, IOBuffer, PolyDataPiece,
    RectilinearGridPiece, UnstructuredGridPiece, Version, VertexNumbers, Vtk,
};

/// Why a series could not be written.
#[derive(Debug, thiserror::Error)]
pub enum VtkError {
    #[error("cannot write the VTK series in {dir}: {message}")]
    Create { dir: PathBuf, message: String },
    #[error("VTK series {path}: {message}")]
    Write { path: PathBuf, message: String },
}

/// Samples per B-spline segment (as the TUI and the recordings draw them).
pub const SAMPLES_PER_SEGMENT: usize = 16;

/// One kind of file and its `.pvd` collection, kept valid after every
/// step: the closing tags are rewritten after each new entry.
struct Series {
    name: &'static str,
    ext: &'static str,
    pvd: File,
    pvd_path: PathBuf,
    /// Where the closing tags start (the next entry goes there).
    tail: u64,
}

const PVD_HEAD: &str =
    "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n";
const PVD_TAIL: &str = "  </Collection>\n</VTKFile>\n";

impl Series {
    fn create(dir: &Path, name: &'static str, ext: &'static str) -> std::io::Result<Series> {
        std::fs::create_dir_all(dir.join(name))?;
        let pvd_path = dir.join(format!("{name}.pvd"));
        let mut pvd = File::create(&pvd_path)?;
        pvd.write_all(PVD_HEAD.as_bytes())?;
        pvd.write_all(PVD_TAIL.as_bytes())?;
        Ok(Series {
            name,
            ext,
            pvd,
            pvd_path,
            tail: PVD_HEAD.len() as u64,
        })
    }

    /// The file of `step`, relative to the folder.
    fn file(&self, step: usize) -> String {
        format!("{}/{step:06}.{}", self.name, self.ext)
    }

    /// Write `vtk` as the file of `step` and list it at `time`; the bytes written.
    fn add(&mut self, dir: &Path, step: usize, time: f64, vtk: Vtk) -> Result<u64, VtkError> {
        let rel = self.file(step);
        let path = dir.join(&rel);
        let werr = |p: &Path, m: String| VtkError::Write {
            path: p.to_path_buf(),
            message: m,
        };
        // vtkio's own `export` drops its buffered writer unflushed (an
        // error at the last flush, a full disk, would go unnoticed), so the
        // file is written and flushed here.
        // Written as `FILE.partial` and renamed: the collection lists
        // whole files only, and a write error leaves no half file.
        let partial = crate::output::partial_of(&path);
        let written = (|| {
            let file = File::create(&partial).map_err(|e| e.to_string())?;
            let mut w = BufWriter::new(file);
            vtk.write_xml(&mut w).map_err(|e| e.to_string())?;
            let file = w.into_inner().map_err(|e| e.error().to_string())?;
            let bytes = file.metadata().map(|m| m.len()).unwrap_or(0);
            std::fs::rename(&partial, &path).map_err(|e| e.to_string())?;
            Ok::<u64, String>(bytes)
        })();
        let bytes = written.map_err(|e| {
            let _ = std::fs::remove_file(&partial);
            werr(&path, e)
        })?;
        let entry = format!("    <DataSet timestep=\"{time}\" group=\"\" part=\"0\" file=\"{rel}\"/>\n");
        let pvd_err = |e: std::io::Error| werr(&self.pvd_path, e.to_string());
        self.pvd.seek(SeekFrom::Start(self.tail)).map_err(pvd_err)?;
        self.pvd.write_all(entry.as_bytes()).map_err(pvd_err)?;
        self.pvd.write_all(PVD_TAIL.as_bytes()).map_err(pvd_err)?;
        self.pvd.flush().map_err(pvd_err)?;
        self.tail += entry.len() as u64;
        Ok(bytes)
    }
}

/// What a finished series holds.
#[derive(Clone, Debug, PartialEq)]
pub struct VtkSummary {
    pub dir: PathBuf,
    /// States written (the initial state counted).
    pub frames: usize,
    /// Bytes of every file written (the `.pvd` files not counted).
    pub bytes: u64,
    /// States not written because a value was not finite.
    pub skipped: usize,
}

impl std::fmt::Display for VtkSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} (open points.pvd in ParaView): {} states, {}",
            self.dir.display(),
            self.frames,
            crate::format::human_bytes(self.bytes as f64)
        )?;
        if self.skipped > 0 {
            write!(f, "; {} states with non-finite values not written", self.skipped)?;
        }
        Ok(())
    }
}

/// Writes a run's states to a folder as ParaView series.
pub struct VtkExport {
    dir: PathBuf,
    /// The folder's lock, held while the series is written.
    _lock: File,
    every: usize,
    points: Series,
    grid: Series,
    boundaries: Option<Series>,
    ibm: Option<Series>,
    /// The step of the last state handled (written or skipped).
    last: Option<usize>,
    frames: usize,
    bytes: u64,
    skipped: usize,
}

/// The lock file of a series folder.
const LOCK: &str = ".mpmlab-vtk.lock";

/// What a series writes in its folder: anything else is the user's.
const SERIES_ENTRIES: &[&str] = &[
    "points.pvd",
    "grid.pvd",
    "boundaries.pvd",
    "ibm.pvd",
    "points",
    "grid",
    "boundaries",
    "ibm",
    LOCK,
];

impl VtkExport {
    /// Create the folder (if needed) and the collections, and write the
    /// initial state. `every`: write every `every`-th step (at least 1).
    pub fn create(dir: &Path, sim: &Simulation, every: usize, force: bool) -> Result<VtkExport, VtkError> {
        let err = |m: String| VtkError::Create {
            dir: dir.to_path_buf(),
            message: m,
        };
        if dir.exists() && !dir.is_dir() {
            return Err(err("it exists and is not a directory".into()));
        }
        std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
        // Another series' files are replaced; anything else is the user's.
        let (foreign, _) = crate::output::foreign_entries(dir, SERIES_ENTRIES);
        if !foreign.is_empty() && !force {
            return Err(err(format!(
                "the folder holds files that are not a ParaView series of this program ({}); \
                 choose another folder, or --force to write beside them",
                crate::output::some_of(&foreign)
            )));
        }
        let Some(lock) = crate::output::lock_file(&dir.join(LOCK)).map_err(err)? else {
            return Err(err(
                "another run is writing a series to it; wait for it or choose another folder".into(),
            ));
        };
        let series = |name, ext| Series::create(dir, name, ext).map_err(|e| err(e.to_string()));
        let m = sim.model();
        let mut v = VtkExport {
            dir: dir.to_path_buf(),
            _lock: lock,
            every: every.max(1),
            points: series("points", "vtu")?,
            grid: series("grid", "vtr")?,
            boundaries: if m.boundaries.is_empty() {
                None
            } else {
                Some(series("boundaries", "vtp")?)
            },
            ibm: if m.ibm.is_empty() {
                None
            } else {
                Some(series("ibm", "vtp")?)
            },
            last: None,
            frames: 0,
            bytes: 0,
            skipped: 0,
        };
        v.write_state(sim)?;
        Ok(v)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Write the current state unless it was already handled.
    pub fn write_state(&mut self, sim: &Simulation) -> Result<(), VtkError> {
        let step = sim.step_index();
        if self.last == Some(step) {
            return Ok(());
        }
        self.last = Some(step);
        let Some(points) = points_vtk(sim) else {
            self.skipped += 1;
            return Ok(());
        };
        let boundaries = boundaries_vtk(sim);
        let ibm = ibm_vtk(sim);
        if boundaries.is_none() && self.boundaries.is_some() || ibm.is_none() && self.ibm.is_some() {
            self.skipped += 1;
            return Ok(());
        }
        let time = sim.time().unwrap_or_else(|| sim.load_factor());
        let dir = self.dir.clone();
        self.bytes += self.points.add(&dir, step, time, points)?;
        self.bytes += self.grid.add(&dir, step, time, grid_vtk(sim))?;
        if let (Some(s), Some(b)) = (self.boundaries.as_mut(), boundaries) {
            self.bytes += s.add(&dir, step, time, b)?;
        }
        if let (Some(s), Some(b)) = (self.ibm.as_mut(), ibm) {
            self.bytes += s.add(&dir, step, time, b)?;
        }
        self.frames += 1;
        Ok(())
    }

    /// Write the last state reached if the cadence left it out, and say
    /// what the series holds.
    pub fn finish(mut self, sim: &Simulation) -> Result<VtkSummary, VtkError> {
        self.write_state(sim)?;
        Ok(VtkSummary {
            dir: self.dir,
            frames: self.frames,
            bytes: self.bytes,
            skipped: self.skipped,
        })
    }
}

impl Observer for VtkExport {
    fn stepped(&mut self, sim: &Simulation, _report: &StepReport) -> Option<String> {
        let step = sim.step_index();
        if !step.is_multiple_of(self.every) && !sim.finished() {
            return None;
        }
        self.write_state(sim).err().map(|e| e.to_string())
    }

    /// The state is the last good step: write it if the cadence left it out.
    fn failed(&mut self, sim: &Simulation, _failure: &StepFailure) -> Option<String> {
        self.write_state(sim).err().map(|e| e.to_string())
    }
}

fn vtk(data: DataSet) -> Vtk {
    Vtk {
        version: Version::new_xml(1, 0),
        byte_order: ByteOrder::LittleEndian,
        title: String::new(),
        file_path: None,
        data,
    }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The points with every per-point value (module docs); `None` when a
/// value is not finite.
pub fn points_vtk(sim: &Simulation) -> Option<Vtk> {
    let pts = sim.points();
    let n = pts.len();
    let m = sim.model();
    let linear = m.analysis.kind == AnalysisKind::QuasiStaticLinear;
    let xyz: Vec<f64> = pts.x.iter().flat_map(|x| [x[0], x[1], 0.0]).collect();
    let displacement: Vec<f64> = (0..n)
        .flat_map(|p| {
            let u = pts.displacement(p);
            [u[0], u[1], 0.0]
        })
        .collect();
    let velocity: Vec<f64> = (0..n)
        .flat_map(|p| {
            let v = pts.velocity(p);
            [v[0], v[1], 0.0]
        })
        .collect();
    let stress: Vec<f64> = (0..n)
        .flat_map(|p| {
            let s = pts.stress[p];
            let szz = if linear {
                m.materials[m.bodies[pts.body[p]].material].elastic.szz(s)
            } else {
                pts.szz[p]
            };
            [s[0], s[2], 0.0, s[2], s[1], 0.0, 0.0, 0.0, szz]
        })
        .collect();
    let mut data = Vec::new();
    for f in Field::ALL {
        let v = f.values(sim);
        if !finite(&v) {
            return None;
        }
        let a = if f == Field::SigmaYy {
            Attribute::scalars(f.key(), 1)
        } else {
            Attribute::generic(f.key(), 1)
        };
        data.push(a.with_data(v));
    }
    for (name, v) in [("volume", &pts.vol), ("mass", &pts.mass)] {
        if !finite(v) {
            return None;
        }
        data.push(Attribute::generic(name, 1).with_data(v.clone()));
    }
    if !(finite(&xyz) && finite(&displacement) && finite(&velocity) && finite(&stress)) {
        return None;
    }
    data.push(Attribute::vectors("displacement").with_data(displacement));
    data.push(Attribute::vectors("velocity").with_data(velocity));
    data.push(Attribute::tensors("stress").with_data(stress));
    let body: Vec<i32> = pts.body.iter().map(|&b| b as i32).collect();
    data.push(Attribute::generic("body", 1).with_data(body));
    let yielding: Vec<u8> = (0..n).map(|p| u8::from(pts.yielding_at(p))).collect();
    data.push(Attribute::generic("yielding", 1).with_data(yielding));
    Some(vtk(DataSet::inline(UnstructuredGridPiece {
        points: IOBuffer::new(xyz),
        cells: Cells {
            cell_verts: VertexNumbers::XML {
                connectivity: (0..n as u64).collect(),
                offsets: (1..=n as u64).collect(),
            },
            types: vec![CellType::Vertex; n],
        },
        data: Attributes {
            point: data,
            cell: vec![],
        },
    })))
}

/// Polylines with per-line cell data.
fn lines_vtk(lines: &[Vec<[f64; 2]>], cell: Vec<Attribute>) -> Option<Vtk> {
    let xyz: Vec<f64> = lines.iter().flatten().flat_map(|p| [p[0], p[1], 0.0]).collect();
    if !finite(&xyz) {
        return None;
    }
    let total: usize = lines.iter().map(Vec::len).sum();
    let mut offsets = Vec::with_capacity(lines.len());
    let mut end = 0u64;
    for l in lines {
        end += l.len() as u64;
        offsets.push(end);
    }
    Some(vtk(DataSet::inline(PolyDataPiece {
        points: IOBuffer::new(xyz),
        lines: Some(VertexNumbers::XML {
            connectivity: (0..total as u64).collect(),
            offsets,
        }),
        data: Attributes { point: vec![], cell },
        ..Default::default()
    })))
}

/// The B-spline boundaries through the current points, sampled
/// [`SAMPLES_PER_SEGMENT`] times per segment (a boundary whose spline
/// cannot be built is left out); `None` when a sample is not finite.
pub fn boundaries_vtk(sim: &Simulation) -> Option<Vtk> {
    let model = sim.model();
    let (mut lines, mut index, mut traction) = (Vec::new(), Vec::new(), Vec::new());
    for (i, ((_, spline), b)) in sim.boundary_splines().into_iter().zip(&model.boundaries).enumerate() {
        let Some(s) = spline else { continue };
        lines.push(s.sample(SAMPLES_PER_SEGMENT));
        index.push(i as i32);
        traction.push(u8::from(b.traction.is_some()));
    }
    lines_vtk(
        &lines,
        vec![
            Attribute::generic("boundary", 1).with_data(index),
            Attribute::generic("traction", 1).with_data(traction),
        ],
    )
}

/// The implicit (IBM) Dirichlet boundaries at their current position;
/// `None` when a point is not finite.
pub fn ibm_vtk(sim: &Simulation) -> Option<Vtk> {
    let model = sim.model();
    let (mut lines, mut index) = (Vec::new(), Vec::new());
    for b in sim.ibm_boundaries() {
        let i = model.ibm.iter().position(|m| m.name == b.name).unwrap_or(0);
        lines.push(b.points);
        index.push(i as i32);
    }
    lines_vtk(&lines, vec![Attribute::generic("boundary", 1).with_data(index)])
}

/// The grid with the cells holding points marked `active`.
pub fn grid_vtk(sim: &Simulation) -> Vtk {
    let g = &sim.model().grid;
    let mut active = vec![0u8; g.num_cells()];
    for &c in sim.active_cells() {
        if let Some(a) = active.get_mut(c) {
            *a = 1;
        }
    }
    let x: Vec<f64> = (0..=g.nx).map(|i| g.origin[0] + i as f64 * g.h).collect();
    let y: Vec<f64> = (0..=g.ny).map(|j| g.origin[1] + j as f64 * g.h).collect();
    vtk(DataSet::inline(RectilinearGridPiece {
        extent: Extent::Ranges([0..=g.nx as i32, 0..=g.ny as i32, 0..=0]),
        coords: Coordinates {
            x: IOBuffer::new(x),
            y: IOBuffer::new(y),
            z: IOBuffer::new(vec![0.0f64]),
        },
        data: Attributes {
            point: vec![],
            cell: vec![Attribute::generic("active", 1).with_data(active)],
        },
    }))
}
