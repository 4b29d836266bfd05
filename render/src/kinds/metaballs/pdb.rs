//! Atoms of a Protein Data Bank file as metaballs, like the Molecule scenes of
//! fitted-bvh-metaballs.txt §6: one ball per `ATOM`/`HETATM` record, its support twice the
//! element's van der Waals radius (so a lone atom's surface at Wyvill `T = 0.5` is its van
//! der Waals sphere) and its colour the element's CPK colour. Parses a `&str`; reading the
//! file is the caller's business, so the engine stays file-free.

use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::scene::{Metaball, MetaballScene};
use glam::Vec3;

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

/// One atom record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Atom {
    pub position: Vec3,
    pub element: Element,
}

/// A record that could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("PDB line {line}: {reason}")]
pub struct PdbError {
    pub line: usize,
    pub reason: String,
}

/// Every `ATOM` and `HETATM` record of the first model (reading stops at `ENDMDL`).
pub fn parse_pdb(text: &str) -> Result<Vec<Atom>, PdbError> {
    let mut atoms = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        if line.starts_with("ENDMDL") {
            break;
        }
        if !(line.starts_with("ATOM") || line.starts_with("HETATM")) {
            continue;
        }
        let field = |a: usize, b: usize| line.get(a..b.min(line.len())).unwrap_or("");
        let coord = |a: usize, b: usize, name: &str| -> Result<f32, PdbError> {
            let v: f32 = field(a, b).trim().parse().map_err(|_| PdbError {
                line: line_no,
                reason: format!("{name} {:?} is not a number", field(a, b)),
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(PdbError {
                    line: line_no,
                    reason: format!("{name} is not finite"),
                })
            }
        };
        let position = Vec3::new(
            coord(30, 38, "x")?,
            coord(38, 46, "y")?,
            coord(46, 54, "z")?,
        );
        let element = element_of(field(76, 78), field(12, 16), line.starts_with("HETATM"));
        atoms.push(Atom { position, element });
    }
    Ok(atoms)
}

/// The element of a record: the symbol in columns 77–78 when it is one (old files keep a
/// serial number there), else the atom name's columns 13–14, where PDB right-justifies the
/// symbol: " CA " is a carbon (alpha), "CA  " in a `HETATM` calcium, "1HG1" a hydrogen.
fn element_of(symbol: &str, name: &str, hetero: bool) -> Element {
    let symbol = symbol.trim();
    if !symbol.is_empty() && symbol.chars().all(|c| c.is_ascii_alphabetic()) {
        return Element::from_symbol(symbol);
    }
    let name: Vec<char> = name.chars().collect();
    let first = name.first().copied().unwrap_or(' ');
    let second = name.get(1).copied().unwrap_or(' ');
    if first == ' ' || first.is_ascii_digit() {
        return Element::from_symbol(&second.to_string());
    }
    if hetero && second.is_ascii_alphabetic() {
        let two = Element::from_symbol(&format!("{first}{second}"));
        if two != Element::Other {
            return two;
        }
    }
    Element::from_symbol(&first.to_string())
}

/// The atoms as Wyvill balls, centred on their centroid.
pub fn molecule_scene(atoms: &[Atom]) -> MetaballScene {
    let centroid = atoms.iter().map(|a| a.position).sum::<Vec3>() / atoms.len().max(1) as f32;
    let balls = atoms
        .iter()
        .map(|a| {
            Metaball::sphere(
                a.position - centroid,
                2.0 * a.element.van_der_waals_radius(),
                1.0,
                a.element.cpk_color(),
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

    const WATER: &str = "\
HEADER    TINY TEST
ATOM      1  O   HOH A   1       0.000   0.000   0.000  1.00  0.00           O
ATOM      2  H1  HOH A   1       0.957   0.000   0.000  1.00  0.00           H
HETATM    3  H2  HOH A   1      -0.240   0.927   0.000  1.00  0.00
HETATM    4 FE   HEM A   2       1.000   1.000   1.000  1.00  0.00      1HPV 186
HETATM    5 1HG1 VAL A   3       2.000   1.000   1.000  1.00  0.00
ATOM      6  CA  GLY A   4       3.000   1.000   1.000  1.00  0.00      1HPV 187
ENDMDL
ATOM      4  C   XXX A   2       9.000   9.000   9.000  1.00  0.00           C
";

    #[test]
    fn parses_atoms_elements_and_stops_at_the_first_model() {
        let atoms = parse_pdb(WATER).expect("parses");
        assert_eq!(atoms.len(), 6);
        assert_eq!(atoms[0].element, Element::O);
        assert_eq!(atoms[1].element, Element::H);
        assert_eq!(atoms[2].element, Element::H, "from the atom name");
        assert_eq!(atoms[3].element, Element::Fe, "a two-letter hetero atom");
        assert_eq!(atoms[4].element, Element::H, "a digit before the symbol");
        assert_eq!(atoms[5].element, Element::C, "an alpha carbon, not calcium");
        assert!((atoms[1].position.x - 0.957).abs() < 1e-6);
        let scene = molecule_scene(&atoms);
        assert_eq!(scene.balls.len(), 6);
        assert!((scene.balls[0].radius - 3.04).abs() < 1e-6);
        scene.validate(10).expect("valid");
    }

    #[test]
    fn a_bad_coordinate_names_its_line() {
        let bad =
            "ATOM      1  O   HOH A   1       0.000   abcde   0.000  1.00  0.00           O\n";
        let err = parse_pdb(bad).expect_err("rejects");
        assert_eq!(err.line, 1);
    }
}
