//! The scene store on disk: pushed scenes and their time steps under a data directory, written
//! crash-safely, reloaded and checksum-verified on start, trimmed by a retention policy.
//!
//! Layout under the data directory:
//!
//! ```text
//! scenes/<id>/scene.json          what the scene was created with, and its token's SHA-256
//! scenes/<id>/mesh.bin            a tet scene's mesh, when sent after creation (see `mesh`)
//! scenes/<id>/steps/<index>.step  one file per step (see `format`), 20-digit index
//! scenes/<id>/steps/.tmp-*        a push in progress (removed on start)
//! trash/                          deleted scenes on their way out (emptied on start)
//! ```
//!
//! Crash safety: every file is written under a `.tmp-` name, fsynced, renamed into place and
//! the directory fsynced, so after a crash a step is either wholly present or absent. On start
//! every step's header and payload checksum are verified; a damaged step is renamed to
//! `.corrupt` with a log line and not served, and temporary files are removed.
//!
//! Memory mapping: a loaded step's file is mapped read-only (the `filebuffer` crate, a safe API
//! over `mmap`, so the server keeps `unsafe_code = "forbid"`), and its payload is served and
//! turned into primitives straight from the mapping. The contract that makes this sound is
//! the store's own: a step file is written once under a temporary name, made read-only, and
//! renamed into place; nothing opens it for writing again. Replacing a step renames a new file
//! over the name and deleting unlinks it, and an existing mapping keeps the old inode alive,
//! so a mapped view never changes underneath a reader. Editing the data directory by hand
//! while the server runs is outside this contract, as it is for any database.
//!
//! Architecture invariant: everything here blocks on the file system; the HTTP handlers call
//! it through `spawn_blocking`, never on the async runtime's threads.

pub mod format;
pub mod ingest;
pub mod mesh;

use crate::kinds::SceneSetup;
use filebuffer::FileBuffer;
use format::{checksum_hex, verify_payload, StepHeader, HEADER_LEN};
use ingest::WrittenStep;
use isoray_protocol::api::{CreateScene, SceneKind, StepInfo};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};

/// How much the store keeps; the oldest steps (by write order) go first.
#[derive(Clone, Copy, Debug)]
pub struct Retention {
    pub max_steps_per_scene: usize,
    pub max_bytes_per_scene: u64,
    pub max_total_bytes: u64,
}

/// What a scene was created with, as stored in `scene.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneMeta {
    pub id: String,
    pub kind: SceneKind,
    pub spec: CreateScene,
    /// Hex SHA-256 of the write token; the token itself is never stored.
    pub write_token_sha256: String,
    pub created_unix_secs: u64,
}

/// One stored step, its file memory-mapped.
pub struct StoredStep {
    pub header: StepHeader,
    pub file_bytes: u64,
    /// Write order across the whole store: retention evicts the smallest first.
    seq: u64,
    map: FileBuffer,
    path: PathBuf,
}

impl StoredStep {
    /// The values: `rows × columns` little-endian f32.
    pub fn payload(&self) -> &[u8] {
        &self.map[HEADER_LEN..]
    }

    pub fn info(&self) -> StepInfo {
        StepInfo {
            index: self.header.index,
            time: self.header.time,
            primitives: self.header.rows,
            columns: self.header.columns,
            bytes: self.file_bytes,
            checksum: checksum_hex(self.header.checksum),
        }
    }

    /// Re-reads the mapped payload and checks it against the header.
    pub fn verify(&self) -> Result<(), format::FormatError> {
        verify_payload(&self.header, self.payload())
    }
}

/// A pushed scene and its steps.
pub struct StoredScene {
    pub meta: SceneMeta,
    /// `meta.spec`, validated and converted.
    pub setup: SceneSetup,
    dir: PathBuf,
    steps: RwLock<BTreeMap<u64, Arc<StoredStep>>>,
    /// Serialises commits, deletions and evictions of this scene's steps.
    commit: Mutex<()>,
}

impl StoredScene {
    pub fn steps(&self) -> Vec<Arc<StoredStep>> {
        self.read_steps().values().cloned().collect()
    }

    pub fn step(&self, index: u64) -> Option<Arc<StoredStep>> {
        self.read_steps().get(&index).cloned()
    }

    pub fn latest(&self) -> Option<Arc<StoredStep>> {
        self.read_steps().values().next_back().cloned()
    }

    /// The step with the largest time not after `time`, else the first.
    pub fn at_time(&self, time: f64) -> Option<Arc<StoredStep>> {
        let steps = self.read_steps();
        steps
            .values()
            .filter(|s| s.header.time <= time)
            .max_by(|a, b| a.header.time.total_cmp(&b.header.time))
            .or_else(|| steps.values().next())
            .cloned()
    }

    pub fn stored_bytes(&self) -> u64 {
        self.read_steps().values().map(|s| s.file_bytes).sum()
    }

    fn read_steps(&self) -> std::sync::RwLockReadGuard<'_, BTreeMap<u64, Arc<StoredStep>>> {
        self.steps.read().unwrap_or_else(|e| e.into_inner())
    }

    fn write_steps(&self) -> std::sync::RwLockWriteGuard<'_, BTreeMap<u64, Arc<StoredStep>>> {
        self.steps.write().unwrap_or_else(|e| e.into_inner())
    }

    fn steps_dir(&self) -> PathBuf {
        self.dir.join("steps")
    }

    /// The scene's directory (static data such as a tet mesh lives beside `scene.json`).
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// What a commit did.
pub enum CommitOutcome {
    Created(Arc<StoredStep>),
    /// Same index, same content: nothing changed.
    Unchanged(Arc<StoredStep>),
    Replaced(Arc<StoredStep>),
}

/// Why a commit did not happen.
#[derive(Debug, thiserror::Error)]
pub enum CommitError {
    #[error("step {index} already exists with different content (checksum {existing}); push with ?replace=true to overwrite it")]
    Conflict { index: u64, existing: String },
    #[error("the scene was deleted")]
    SceneGone,
    #[error("store i/o failed: {0}")]
    Io(#[from] std::io::Error),
}

/// Errors opening the store.
#[derive(Debug, thiserror::Error)]
#[error("cannot use data directory {path}: {source}")]
pub struct OpenError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

/// The data directory and the accounting that retention needs.
pub struct Store {
    root: PathBuf,
    retention: Retention,
    next_seq: AtomicU64,
    scenes: RwLock<BTreeMap<String, Arc<StoredScene>>>,
    /// Serialises store-wide eviction.
    budget: Mutex<()>,
}

impl Store {
    /// Opens (creating if needed) the data directory and loads every stored scene, verifying
    /// each step's checksum and removing temporary files left by a crash.
    pub fn open(root: &Path, retention: Retention) -> Result<Store, OpenError> {
        let err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| OpenError { path, source }
        };
        let scenes_dir = root.join("scenes");
        let trash = root.join("trash");
        std::fs::create_dir_all(&scenes_dir).map_err(err(&scenes_dir))?;
        std::fs::create_dir_all(&trash).map_err(err(&trash))?;
        empty_dir(&trash);
        let store = Store {
            root: root.to_path_buf(),
            retention,
            next_seq: AtomicU64::new(0),
            scenes: RwLock::new(BTreeMap::new()),
            budget: Mutex::new(()),
        };
        // Steps load in write order (file modification time) so retention evicts the oldest.
        let mut loaded: Vec<(std::time::SystemTime, Arc<StoredScene>, PathBuf)> = Vec::new();
        let mut scenes = BTreeMap::new();
        for dir in std::fs::read_dir(&scenes_dir).map_err(err(&scenes_dir))? {
            let dir = dir.map_err(err(&scenes_dir))?.path();
            let name = file_name(&dir);
            if name.starts_with(".tmp-") {
                tracing::info!(path = %dir.display(), "removing a scene whose creation was interrupted");
                remove_all(&dir);
                continue;
            }
            match load_scene(&dir) {
                Ok((scene, steps)) => {
                    let scene = Arc::new(scene);
                    for (mtime, path) in steps {
                        loaded.push((mtime, Arc::clone(&scene), path));
                    }
                    scenes.insert(scene.meta.id.clone(), scene);
                }
                Err(e) => {
                    tracing::warn!(path = %dir.display(), error = %e, "skipping an unreadable scene directory")
                }
            }
        }
        loaded.sort_by(|a, b| {
            a.0.cmp(&b.0)
                .then_with(|| a.1.meta.id.cmp(&b.1.meta.id))
                .then_with(|| a.2.cmp(&b.2))
        });
        let mut count = 0usize;
        for (_, scene, path) in loaded {
            match open_step(&path, store.take_seq()) {
                Ok(step) if file_name(&path) != format!("{:020}.step", step.header.index) => {
                    drop(step);
                    quarantine(&path, "the file name does not match the step index inside");
                }
                Ok(step)
                    if !scene
                        .setup
                        .layout()
                        .allowed_columns()
                        .contains(&step.header.columns) =>
                {
                    drop(step);
                    quarantine(
                        &path,
                        "the step's column count does not fit the scene's kind",
                    );
                }
                Ok(step) => {
                    scene
                        .write_steps()
                        .insert(step.header.index, Arc::new(step));
                    count += 1;
                }
                Err(e) => quarantine(&path, &e.to_string()),
            }
        }
        tracing::info!(
            dir = %root.display(),
            scenes = scenes.len(),
            steps = count,
            "scene store loaded; every step's checksum verified"
        );
        *store.scenes.write().unwrap_or_else(|e| e.into_inner()) = scenes;
        Ok(store)
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn retention(&self) -> Retention {
        self.retention
    }

    pub fn scenes(&self) -> Vec<Arc<StoredScene>> {
        self.read_scenes().values().cloned().collect()
    }

    fn read_scenes(&self) -> std::sync::RwLockReadGuard<'_, BTreeMap<String, Arc<StoredScene>>> {
        self.scenes.read().unwrap_or_else(|e| e.into_inner())
    }

    fn take_seq(&self) -> u64 {
        self.next_seq.fetch_add(1, Ordering::Relaxed)
    }

    /// Bytes of every stored step.
    pub fn total_bytes(&self) -> u64 {
        self.read_scenes().values().map(|s| s.stored_bytes()).sum()
    }

    /// Writes a new scene's directory crash-safely and registers it. A failed write (a full
    /// disk) removes the partial `.tmp-<id>` directory at once.
    pub fn create_scene(
        &self,
        meta: SceneMeta,
        setup: SceneSetup,
    ) -> std::io::Result<Arc<StoredScene>> {
        let scenes_dir = self.root.join("scenes");
        let temp = scenes_dir.join(format!(".tmp-{}", meta.id));
        let dir = scenes_dir.join(&meta.id);
        if let Err(e) = write_scene_dir(&temp, &meta) {
            if let Err(cleanup) = std::fs::remove_dir_all(&temp) {
                tracing::warn!(path = %temp.display(), error = %cleanup, "cannot remove a failed scene's directory");
            }
            return Err(e);
        }
        std::fs::rename(&temp, &dir)?;
        sync_dir(&scenes_dir)?;
        let scene = Arc::new(StoredScene {
            meta,
            setup,
            dir,
            steps: RwLock::new(BTreeMap::new()),
            commit: Mutex::new(()),
        });
        self.scenes
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(scene.meta.id.clone(), Arc::clone(&scene));
        Ok(scene)
    }

    /// A fresh temporary path for a push into `scene`.
    pub fn temp_step_path(&self, scene: &StoredScene) -> PathBuf {
        scene
            .steps_dir()
            .join(format!(".tmp-{}.step", crate::random::random_hex(8)))
    }

    /// Puts a written step in place (or finds it already there), then applies retention.
    /// Returns the outcome and the indices of steps evicted from this scene.
    pub fn commit(
        &self,
        scene: &StoredScene,
        written: WrittenStep,
        replace: bool,
    ) -> Result<(CommitOutcome, Vec<u64>), CommitError> {
        let _guard = scene.commit.lock().unwrap_or_else(|e| e.into_inner());
        if !scene.dir.exists() {
            return Err(CommitError::SceneGone);
        }
        let index = written.header.index;
        let existing = scene.step(index);
        if let Some(old) = &existing {
            if old.header == written.header {
                return Ok((CommitOutcome::Unchanged(Arc::clone(old)), Vec::new()));
            }
            if !replace {
                return Err(CommitError::Conflict {
                    index,
                    existing: checksum_hex(old.header.checksum),
                });
            }
        }
        let path = scene.steps_dir().join(format!("{index:020}.step"));
        std::fs::rename(written.temp.path(), &path)?;
        written.temp.keep();
        sync_dir(&scene.steps_dir())?;
        let step = Arc::new(open_step_trusted(&path, self.take_seq())?);
        scene.write_steps().insert(index, Arc::clone(&step));
        let mut evicted = self.enforce_scene_retention(scene, index);
        drop(_guard);
        evicted.extend(self.enforce_total_budget(&scene.meta.id, index));
        let outcome = if existing.is_some() {
            CommitOutcome::Replaced(step)
        } else {
            CommitOutcome::Created(step)
        };
        Ok((outcome, evicted))
    }

    /// Evicts this scene's oldest steps past its step and byte limits; never `keep`.
    fn enforce_scene_retention(&self, scene: &StoredScene, keep: u64) -> Vec<u64> {
        let mut evicted = Vec::new();
        loop {
            let steps = scene.steps();
            let bytes: u64 = steps.iter().map(|s| s.file_bytes).sum();
            let over_count = steps.len() > self.retention.max_steps_per_scene;
            let over_bytes = bytes > self.retention.max_bytes_per_scene;
            if !over_count && !over_bytes {
                break;
            }
            let Some(oldest) = steps
                .iter()
                .filter(|s| s.header.index != keep)
                .min_by_key(|s| s.seq)
            else {
                break;
            };
            let reason = if over_count {
                "steps per scene"
            } else {
                "bytes per scene"
            };
            evict(scene, oldest, reason);
            evicted.push(oldest.header.index);
        }
        evicted
    }

    /// Evicts the store's oldest steps while it is over its total budget. Returns what it
    /// evicted from scene `this_scene` (other scenes' evictions are only logged).
    fn enforce_total_budget(&self, this_scene: &str, keep: u64) -> Vec<u64> {
        let _guard = self.budget.lock().unwrap_or_else(|e| e.into_inner());
        let mut evicted = Vec::new();
        while self.total_bytes() > self.retention.max_total_bytes {
            let scenes = self.scenes();
            let oldest = scenes
                .iter()
                .flat_map(|sc| sc.steps().into_iter().map(move |st| (Arc::clone(sc), st)))
                .filter(|(sc, st)| !(sc.meta.id == this_scene && st.header.index == keep))
                .min_by_key(|(_, st)| st.seq);
            let Some((scene, step)) = oldest else { break };
            let _commit = scene.commit.lock().unwrap_or_else(|e| e.into_inner());
            evict(&scene, &step, "total store budget");
            if scene.meta.id == this_scene {
                evicted.push(step.header.index);
            }
        }
        evicted
    }

    /// Removes one step. Returns whether it existed.
    pub fn delete_step(&self, scene: &StoredScene, index: u64) -> std::io::Result<bool> {
        let _guard = scene.commit.lock().unwrap_or_else(|e| e.into_inner());
        let Some(step) = scene.write_steps().remove(&index) else {
            return Ok(false);
        };
        std::fs::remove_file(&step.path)?;
        sync_dir(&scene.steps_dir())?;
        Ok(true)
    }

    /// Removes a scene: renamed into `trash/` (atomic), then deleted.
    pub fn delete_scene(&self, id: &str) -> std::io::Result<bool> {
        let Some(scene) = self
            .scenes
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .remove(id)
        else {
            return Ok(false);
        };
        let _guard = scene.commit.lock().unwrap_or_else(|e| e.into_inner());
        let trash = self
            .root
            .join("trash")
            .join(format!("{id}-{}", crate::random::random_hex(4)));
        std::fs::rename(&scene.dir, &trash)?;
        sync_dir(&self.root.join("scenes"))?;
        remove_all(&trash);
        Ok(true)
    }

    /// Finds a scene.
    pub fn get(&self, id: &str) -> Option<Arc<StoredScene>> {
        self.read_scenes().get(id).cloned()
    }
}

fn evict(scene: &StoredScene, step: &StoredStep, reason: &str) {
    scene.write_steps().remove(&step.header.index);
    match std::fs::remove_file(&step.path) {
        Ok(()) => tracing::info!(
            scene = %scene.meta.id,
            index = step.header.index,
            bytes = step.file_bytes,
            reason,
            "retention evicted the oldest step"
        ),
        Err(e) => tracing::warn!(
            scene = %scene.meta.id,
            index = step.header.index,
            error = %e,
            "retention could not remove a step file"
        ),
    }
}

type LoadedSteps = Vec<(std::time::SystemTime, PathBuf)>;

/// Reads `scene.json`, removes temporary step files, and lists the step files (they are
/// verified when opened).
fn load_scene(dir: &Path) -> Result<(StoredScene, LoadedSteps), String> {
    let json = std::fs::read(dir.join("scene.json")).map_err(|e| format!("scene.json: {e}"))?;
    let meta: SceneMeta = serde_json::from_slice(&json).map_err(|e| format!("scene.json: {e}"))?;
    if meta.id != file_name(dir) {
        return Err(format!("scene.json names scene {}", meta.id));
    }
    let setup =
        SceneSetup::from_spec(&meta.spec, &crate::effects::EffectLimits::ENGINE).map_err(|e| {
            format!(
                "scene.json: {} ({})",
                e.message,
                e.field.as_deref().unwrap_or("spec")
            )
        })?;
    mesh::attach(dir, &setup);
    let steps_dir = dir.join("steps");
    let mut steps = Vec::new();
    let entries = std::fs::read_dir(&steps_dir).map_err(|e| format!("steps/: {e}"))?;
    for entry in entries.flatten() {
        let path = entry.path();
        let name = file_name(&path);
        if name.starts_with(".tmp-") {
            tracing::info!(path = %path.display(), "removing a step whose push was interrupted");
            if let Err(e) = std::fs::remove_file(&path) {
                tracing::warn!(path = %path.display(), error = %e, "cannot remove a temporary file");
            }
            continue;
        }
        if !name.ends_with(".step") {
            continue;
        }
        let mtime = entry
            .metadata()
            .and_then(|m| m.modified())
            .unwrap_or(std::time::UNIX_EPOCH);
        steps.push((mtime, path));
    }
    sync_dir(&steps_dir).map_err(|e| format!("steps/: {e}"))?;
    Ok((
        StoredScene {
            meta,
            setup,
            dir: dir.to_path_buf(),
            steps: RwLock::new(BTreeMap::new()),
            commit: Mutex::new(()),
        },
        steps,
    ))
}

/// Maps a step file and verifies header and payload checksum.
fn open_step(path: &Path, seq: u64) -> Result<StoredStep, String> {
    let step = open_step_trusted(path, seq).map_err(|e| e.to_string())?;
    step.verify().map_err(|e| e.to_string())?;
    Ok(step)
}

/// Maps a step file and checks its header; the payload checksum was computed while writing.
fn open_step_trusted(path: &Path, seq: u64) -> std::io::Result<StoredStep> {
    let map = FileBuffer::open(path)?;
    let header = StepHeader::decode(&map).map_err(std::io::Error::other)?;
    Ok(StoredStep {
        header,
        file_bytes: map.len() as u64,
        seq,
        map,
        path: path.to_path_buf(),
    })
}

/// Takes a damaged step out of service, keeping it for inspection.
fn quarantine(path: &Path, why: &str) {
    let target = path.with_extension("corrupt");
    tracing::error!(path = %path.display(), error = why, "step failed verification; renamed to .corrupt and not served");
    if let Err(e) = std::fs::rename(path, &target) {
        tracing::error!(path = %path.display(), error = %e, "cannot rename a damaged step");
    }
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A new scene's directory under its temporary name: `steps/` and `scene.json`, synced.
fn write_scene_dir(temp: &Path, meta: &SceneMeta) -> std::io::Result<()> {
    std::fs::create_dir_all(temp.join("steps"))?;
    let json = serde_json::to_vec_pretty(meta).map_err(std::io::Error::other)?;
    let mut file = File::create(temp.join("scene.json"))?;
    file.write_all(&json)?;
    file.sync_all()?;
    sync_dir(&temp.join("steps"))?;
    sync_dir(temp)
}

/// fsyncs a directory so renames and unlinks in it are durable.
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

fn remove_all(path: &Path) {
    if let Err(e) = std::fs::remove_dir_all(path) {
        tracing::warn!(path = %path.display(), error = %e, "cannot remove a directory");
    }
}

fn empty_dir(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            remove_all(&entry.path());
        }
    }
}
