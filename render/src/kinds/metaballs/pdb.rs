//! Molecules as metaballs, like the Molecule scenes of fitted-bvh-metaballs.txt §6: one
//! ball per atom, its support `radius_scale` (default 2) times the element's van der Waals
//! radius (Bondi; so a lone atom's surface at Wyvill `T = 0.5` is its van der Waals sphere)
//! and its colour the element's CPK colour. Protein Data Bank (`.pdb`, `.ent`) and mmCIF
//! (`.cif`) files are read with pdbtbx ([`read_models`]); each model is one state.

use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::scene::{Metaball, MetaballScene};
use glam::Vec3;
use pdbtbx::{ContainsAtomConformer, Context, Format, PDBError, ReadOptions, StrictnessLevel};
use std::path::Path;

/// The elements with their own radius and colour; the rest share `Other`'s.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Element {
    H,
    C,
    N,
    O,
    S,
    P,
    F,
    Cl,
    Br,
    I,
    Fe,
    Other,
}

impl Element {
    /// From a PDB element symbol (columns 77–78) or an atom name's leading letters.
    pub fn from_symbol(symbol: &str) -> Element {
        match symbol.trim().to_ascii_uppercase().as_str() {
            "H" | "D" => Element::H,
            "C" => Element::C,
            "N" => Element::N,
            "O" => Element::O,
            "S" => Element::S,
            "P" => Element::P,
            "F" => Element::F,
            "CL" => Element::Cl,
            "BR" => Element::Br,
            "I" => Element::I,
            "FE" => Element::Fe,
            _ => Element::Other,
        }
    }

    /// The element's symbol (`""` for `Other`).
    pub fn symbol(self) -> &'static str {
        match self {
            Element::H => "H",
            Element::C => "C",
            Element::N => "N",
            Element::O => "O",
            Element::S => "S",
            Element::P => "P",
            Element::F => "F",
            Element::Cl => "CL",
            Element::Br => "BR",
            Element::I => "I",
            Element::Fe => "FE",
            Element::Other => "",
        }
    }

    /// Bondi's van der Waals radius, ångström.
    pub fn van_der_waals_radius(self) -> f32 {
        match self {
            Element::H => 1.20,
            Element::C => 1.70,
            Element::N => 1.55,
            Element::O => 1.52,
            Element::S => 1.80,
            Element::P => 1.80,
            Element::F => 1.47,
            Element::Cl => 1.75,
            Element::Br => 1.85,
            Element::I => 1.98,
            Element::Fe => 1.94,
            Element::Other => 1.80,
        }
    }

    /// CPK colour, linear light.
    pub fn cpk_color(self) -> Vec3 {
        match self {
            Element::H => Vec3::new(0.9, 0.9, 0.9),
            Element::C => Vec3::new(0.12, 0.12, 0.12),
            Element::N => Vec3::new(0.05, 0.1, 0.85),
            Element::O => Vec3::new(0.85, 0.02, 0.02),
            Element::S => Vec3::new(0.9, 0.75, 0.05),
            Element::P => Vec3::new(0.95, 0.35, 0.0),
            Element::F | Element::Cl => Vec3::new(0.05, 0.75, 0.05),
            Element::Br => Vec3::new(0.35, 0.05, 0.02),
            Element::I => Vec3::new(0.25, 0.0, 0.45),
            Element::Fe => Vec3::new(0.8, 0.3, 0.05),
            Element::Other => Vec3::new(0.75, 0.4, 0.75),
        }
    }
}

/// What to keep of a molecule, and how large its balls are.
#[derive(Clone, Copy, Debug)]
pub struct MoleculeOptions {
    pub hydrogens: bool,
    pub waters: bool,
    /// Support radius over van der Waals radius.
    pub radius_scale: f32,
}

impl Default for MoleculeOptions {
    /// No hydrogens, no waters, support twice the van der Waals radius.
    fn default() -> MoleculeOptions {
        MoleculeOptions {
            hydrogens: false,
            waters: false,
            radius_scale: 2.0,
        }
    }
}

/// A ball's row of a metaball step: x y z radius strength r g b.
pub type Row = [f32; 8];

/// Whether `path` names a molecule file.
pub fn is_molecule(path: &Path) -> bool {
    matches!(
        path.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .as_deref(),
        Some("pdb" | "ent" | "cif" | "mmcif")
    )
}

fn line_of(context: &Context) -> Option<usize> {
    match context {
        Context::FullLine { linenumber, .. } | Context::Line { linenumber, .. } => {
            Some(*linenumber)
        }
        Context::Range {
            start_linenumber, ..
        }
        | Context::RangeHighlights {
            start_linenumber, ..
        } => Some(*start_linenumber),
        _ => None,
    }
}

/// The first error that refuses the file (not a warning), naming its line (pdbtbx counts
/// lines from 1).
fn describe(errors: &[PDBError]) -> String {
    let refusing = errors.iter().find(|e| e.fails(StrictnessLevel::Loose));
    let Some(e) = refusing.or(errors.first()) else {
        return "unreadable".into();
    };
    let detail = e.long_description().trim();
    match line_of(e.context()) {
        Some(line) => format!("line {line}: {}: {detail}", e.short_description()),
        None => format!("{}: {detail}", e.short_description()),
    }
}

/// A PDB file's text as pdbtbx reads it best. Old PDB files (before format 2.0, still in circulation: pymol-data's 1HPV is one) end every
/// record with the entry's ID and the line's serial number in columns 73–80, where newer
/// files keep the segment, the element and the charge; pdbtbx reads those columns as a
/// charge and refuses the file. In such records the columns are rewritten: no segment, no
/// charge, and the element the atom name implies ([`element_of_name`]); lines keep their
/// numbers.
///
/// Without `waters`, water records become remarks here: pdbtbx files waters with a blank
/// chain id under the chain before them, merging those whose number an amino acid there has
/// into that residue (96 of 1TII's 215), where their name no longer tells them apart.
fn prepare_pdb_text(text: &str, waters: bool) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let record = line.starts_with("ATOM") || line.starts_with("HETATM");
        if record && !waters && line.get(17..20).is_some_and(is_water) {
            out.push_str("REMARK 999 a water, left out\n");
            continue;
        }
        let charge = line.get(78..80).unwrap_or("  ").as_bytes();
        let charge_ok = charge.len() != 2
            || charge == b"  "
            || (charge[0].is_ascii_digit() && matches!(charge[1], b'+' | b'-'));
        match line.get(..72) {
            Some(head) if !charge_ok => {
                out.push_str(head);
                let element = if record {
                    element_of_name(line.get(12..16).unwrap_or(""), line.starts_with("HETATM"))
                } else {
                    ""
                };
                out.push_str(&format!("    {element:>2}  "));
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

/// Whether a residue name is water's.
fn is_water(name: &str) -> bool {
    matches!(name.trim(), "HOH" | "WAT" | "DOD" | "H2O")
}

/// The element an atom name (columns 13–16) implies, where PDB right-justifies the symbol:
/// " CA " is a carbon (alpha), "CA  " in a `HETATM` calcium, "1HG1" a hydrogen.
fn element_of_name(name: &str, hetero: bool) -> &'static str {
    let name: Vec<char> = name.chars().collect();
    let first = name.first().copied().unwrap_or(' ');
    let second = name.get(1).copied().unwrap_or(' ');
    let symbol = |e: Element| e.symbol();
    if first == ' ' || first.is_ascii_digit() {
        return symbol(Element::from_symbol(&second.to_string()));
    }
    if hetero && second.is_ascii_alphabetic() {
        let two = Element::from_symbol(&format!("{first}{second}"));
        if two != Element::Other {
            return symbol(two);
        }
    }
    symbol(Element::from_symbol(&first.to_string()))
}

/// The models of a molecule file as rows of balls, the first model's centre moved to the
/// origin (every model by the same shift); errors name the file and the line.
pub fn read_models(path: &Path, opts: MoleculeOptions) -> Result<Vec<Vec<Row>>, String> {
    let at = |e: String| format!("{}: {e}", path.display());
    let cif = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("cif") || e.eq_ignore_ascii_case("mmcif"));
    let text = std::fs::read_to_string(path).map_err(|e| at(e.to_string()))?;
    let text = if cif {
        text
    } else {
        prepare_pdb_text(&text, opts.waters)
    };
    // pdbtbx 0.12 panics on some inputs (a chain id it does not accept, in `add_atom`);
    // a bad file must give an error, so such a panic becomes one.
    let read = std::panic::catch_unwind(|| {
        ReadOptions::default()
            .set_level(StrictnessLevel::Loose)
            .set_only_atomic_coords(true)
            .set_format(if cif { Format::Mmcif } else { Format::Pdb })
            .read_raw(std::io::BufReader::new(text.as_bytes()))
    })
    .map_err(|_| at("pdbtbx could not read the file (it panicked; see above)".into()))?;
    let (pdb, _warnings) = read.map_err(|errors| at(describe(&errors)))?;
    let mut models = Vec::new();
    for model in pdb.models() {
        let mut rows = Vec::new();
        for h in model.atoms_with_hierarchy() {
            // (mmCIF; a PDB file's waters went in `prepare_pdb_text`.) The conformer's
            // name, not the residue's, which is its first conformer's.
            let water = is_water(h.conformer().name());
            if water && !opts.waters {
                continue;
            }
            let atom = h.atom();
            let symbol = atom
                .element()
                .map(|e| e.symbol().to_string())
                .unwrap_or_else(|| atom.name().trim().chars().take(1).collect());
            let element = Element::from_symbol(&symbol);
            if element == Element::H && !opts.hydrogens {
                continue;
            }
            let (x, y, z) = atom.pos();
            let c = element.cpk_color();
            rows.push([
                x as f32,
                y as f32,
                z as f32,
                opts.radius_scale * element.van_der_waals_radius(),
                1.0,
                c.x,
                c.y,
                c.z,
            ]);
        }
        if rows.is_empty() {
            return Err(at(format!(
                "model {} has no atoms to show (hydrogens and waters are left out unless asked for)",
                models.len() + 1
            )));
        }
        models.push(rows);
    }
    if models.is_empty() {
        return Err(at("no atoms".into()));
    }
    let first = &models[0];
    let n = first.len() as f64;
    let centre = [0, 1, 2].map(|k| (first.iter().map(|r| f64::from(r[k])).sum::<f64>() / n) as f32);
    for row in models.iter_mut().flatten() {
        for k in 0..3 {
            row[k] -= centre[k];
        }
    }
    Ok(models)
}

/// A model's rows as Wyvill balls.
pub fn molecule_scene(rows: &[Row]) -> MetaballScene {
    let balls = rows
        .iter()
        .map(|r| {
            Metaball::sphere(
                Vec3::new(r[0], r[1], r[2]),
                r[3],
                r[4],
                Vec3::new(r[5], r[6], r[7]),
            )
        })
        .collect();
    MetaballScene {
        kernel: Kernel::Wyvill,
        balls,
        min_isovalue: 0.25,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn old_style_line_ids_become_elements_from_the_atom_name() {
        let old = "\
ATOM      1  N   PRO A   1      13.120  39.003   5.159  1.00 55.41      1HPV 186
ATOM      2  CA  PRO A   1      12.941  39.418   6.575  1.00 31.00      1HPV 187
HETATM    3 FE   HEM A   2       1.000   1.000   1.000  1.00  0.00      1HPV 188
HETATM    4 1HG1 VAL A   3       2.000   1.000   1.000  1.00  0.00      1HPV 189
ATOM      5  CA  GLY A   4       3.000   1.000   1.000  1.00  0.00           C  
";
        let cleared = prepare_pdb_text(old, true);
        let lines: Vec<&str> = cleared.lines().collect();
        let element = |l: &str| l.get(76..78).unwrap_or("").trim().to_string();
        assert_eq!(element(lines[0]), "N");
        assert_eq!(element(lines[1]), "C", "an alpha carbon, not calcium");
        assert_eq!(element(lines[2]), "FE", "a two-letter hetero atom");
        assert_eq!(element(lines[3]), "H", "a digit before the symbol");
        assert_eq!(
            lines[4],
            old.lines().nth(4).unwrap_or(""),
            "a new-style line is kept"
        );
        assert!(lines.iter().all(|l| l.len() == 80));
        let water =
            "HETATM 5477  O   HOH     1      19.099   9.698 -13.097  1.00 32.87           O  \n";
        assert!(prepare_pdb_text(water, false).starts_with("REMARK"));
        assert_eq!(prepare_pdb_text(water, true), water);
    }
}
