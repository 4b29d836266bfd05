//! A small meshless shape-matching simulation (Müller et al. 2005, per-node clusters) that
//! drives the demo scenes: the "physics" deforming-point-sampled-surfaces.txt takes as given
//! (§3). Each step gives the node displacements and, by least squares, their Jacobians.
//!
//! How it works: nodes move under gravity; every node's cluster (itself and its 8 nearest
//! rest neighbours of the same body) is matched rigidly to its current positions and pulls
//! its members towards the matched rest shape; bodies bounce off the walls of a box and off
//! each other (as spheres about their centres). Fixed step, no randomness: the same frames
//! on every run.

use crate::kinds::surfels::deform::gradients_by_least_squares;
use crate::kinds::surfels::knn::Grid;
use crate::kinds::surfels::rigid::RigidFrame;
use glam::{Mat3, Vec3};
use std::ops::Range;

/// One body: a range of nodes, its collision radius and whether it stays rigid.
#[derive(Clone, Debug)]
pub struct Body {
    pub nodes: Range<usize>,
    pub radius: f32,
    /// Stiffness in `[0, 1]`: the share of the way to the matched shape per step.
    pub stiffness: f32,
}

/// The simulation state.
#[derive(Clone, Debug)]
pub struct Simulation {
    pub rest: Vec<Vec3>,
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub bodies: Vec<Body>,
    clusters: Vec<Vec<u32>>,
    /// Walls: nodes stay within `[lo, hi]`.
    pub lo: Vec3,
    pub hi: Vec3,
    pub gravity: Vec3,
    pub restitution: f32,
}

impl Simulation {
    pub fn new(rest: Vec<Vec3>, bodies: Vec<Body>, lo: Vec3, hi: Vec3) -> Simulation {
        let mut clusters = Vec::with_capacity(rest.len());
        let mut near = Vec::new();
        for b in &bodies {
            let pts = &rest[b.nodes.clone()];
            let grid = Grid::new(pts);
            for (i, &p) in pts.iter().enumerate() {
                grid.nearest(p, 8.min(pts.len() - 1), Some(i as u32), &mut near);
                let mut c = vec![(b.nodes.start + i) as u32];
                c.extend(near.iter().map(|n| (b.nodes.start + n.0 as usize) as u32));
                clusters.push(c);
            }
        }
        Simulation {
            x: rest.clone(),
            v: vec![Vec3::ZERO; rest.len()],
            rest,
            bodies,
            clusters,
            lo,
            hi,
            gravity: Vec3::new(0.0, -9.8, 0.0),
            restitution: 0.6,
        }
    }

    /// Gives body `b` a velocity.
    pub fn throw(&mut self, b: usize, velocity: Vec3) {
        for i in self.bodies[b].nodes.clone() {
            self.v[i] = velocity;
        }
    }

    /// Moves body `b` rigidly by `offset` (rest shape unchanged).
    pub fn place(&mut self, b: usize, offset: Vec3) {
        for i in self.bodies[b].nodes.clone() {
            self.x[i] += offset;
        }
    }

    /// One time step of `dt` seconds.
    pub fn step(&mut self, dt: f32) {
        let pred: Vec<Vec3> = self
            .x
            .iter()
            .zip(&self.v)
            .map(|(x, v)| *x + dt * (*v + dt * self.gravity))
            .collect();
        let mut goal = vec![Vec3::ZERO; pred.len()];
        let mut count = vec![0u32; pred.len()];
        for c in &self.clusters {
            let rest: Vec<Vec3> = c.iter().map(|&i| self.rest[i as usize]).collect();
            let now: Vec<Vec3> = c.iter().map(|&i| pred[i as usize]).collect();
            let frame = RigidFrame::optimal(&rest, &now, &vec![1.0; c.len()]);
            for (k, &i) in c.iter().enumerate() {
                goal[i as usize] += frame.apply(rest[k]);
                count[i as usize] += 1;
            }
        }
        let mut body_of = vec![0usize; pred.len()];
        for (b, body) in self.bodies.iter().enumerate() {
            for i in body.nodes.clone() {
                body_of[i] = b;
            }
        }
        for i in 0..pred.len() {
            let g = goal[i] / count[i].max(1) as f32;
            let k = self.bodies[body_of[i]].stiffness;
            let new = pred[i] + k * (g - pred[i]);
            self.v[i] = (new - self.x[i]) / dt;
            self.x[i] = new;
        }
        self.collide();
    }

    fn centre(&self, b: usize) -> Vec3 {
        let r = self.bodies[b].nodes.clone();
        let n = r.len().max(1) as f32;
        self.x[r].iter().copied().sum::<Vec3>() / n
    }

    fn collide(&mut self) {
        // Walls: each node of a body is kept inside by its body's radius margin.
        for b in 0..self.bodies.len() {
            let c = self.centre(b);
            let r = self.bodies[b].radius;
            for a in 0..3 {
                let push = (self.lo[a] + r - c[a]).max(0.0) - (c[a] + r - self.hi[a]).max(0.0);
                if push != 0.0 {
                    for i in self.bodies[b].nodes.clone() {
                        self.x[i][a] += push;
                        if self.v[i][a] * push < 0.0 {
                            self.v[i][a] *= -self.restitution;
                        }
                    }
                }
            }
        }
        // Bodies against each other: a node inside another body's sphere is pushed out to
        // its surface, and that body takes the opposite momentum.
        for a in 0..self.bodies.len() {
            for b in 0..self.bodies.len() {
                if a == b {
                    continue;
                }
                let cb = self.centre(b);
                let rb = self.bodies[b].radius;
                let ca = self.centre(a);
                if (ca - cb).length() > self.bodies[a].radius + rb {
                    continue;
                }
                let mut momentum = Vec3::ZERO;
                for i in self.bodies[a].nodes.clone() {
                    let d = self.x[i] - cb;
                    let len = d.length();
                    if len < rb && len > 1e-6 {
                        let n = d / len;
                        self.x[i] = cb + n * rb;
                        let vb = self.v[self.bodies[b].nodes.start];
                        let vn = (self.v[i] - vb).dot(n);
                        if vn < 0.0 {
                            let dv = -(1.0 + self.restitution) * vn * n;
                            self.v[i] += dv;
                            momentum += dv;
                        }
                    }
                }
                let nb = self.bodies[b].nodes.len().max(1) as f32;
                for i in self.bodies[b].nodes.clone() {
                    self.v[i] -= momentum / nb;
                }
            }
        }
    }

    /// The step's node displacements and least-squares Jacobians.
    pub fn deformation(&self) -> (Vec<Vec3>, Vec<Mat3>) {
        let u = self
            .x
            .iter()
            .zip(&self.rest)
            .map(|(x, r)| *x - *r)
            .collect();
        let mut g = vec![Mat3::ZERO; self.rest.len()];
        for b in &self.bodies {
            let r = b.nodes.clone();
            let gb = gradients_by_least_squares(&self.rest[r.clone()], &self.x[r.clone()]);
            g[r].copy_from_slice(&gb);
        }
        (u, g)
    }
}
