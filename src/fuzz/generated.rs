//! Semantic fuzzing: random but valid scenes (shapes from every generator, rigid bodies, FEM
//! solids and cloths with materials inside their valid ranges, random placements, several
//! solvers' time steps) built from a seed, and random actions on the 16 tasks. The simulator
//! may refuse a scene or end an episode with an error naming the object, but must not panic,
//! hang or return a non-finite value.

use modesuite_engine::rng::EnvRng;

/// The surface mesh file generated scenes may name (written into the folder they compile in).
pub const SURFACE_MESH: &str = "fuzz-tetra.obj";
/// The volume mesh file generated scenes may name.
pub const VOLUME_MESH: &str = "fuzz-tets.msh";

/// A random scene, as RON text, from `seed`. Its `Mesh` shapes name [`SURFACE_MESH`] and
/// [`VOLUME_MESH`], resolved against the folder the scene compiles in.
pub fn random_scene(seed: u64) -> String {
    let mut g = Gen(EnvRng::from_seed(seed));
    let substeps = 1 + g.below(4);
    let mut objects = vec![
        "(name: \"ground\", shape: Plane(size: (8.0, 8.0)), body: Static, material: Some(\"m0\"))"
            .to_string(),
    ];
    let mut materials = Vec::new();
    let n = 1 + g.below(3);
    let mut solids = 0;
    for i in 0..=n {
        materials.push(format!(
            "\"m{i}\": (friction: {}, density: {})",
            g.f(0.0, 1.5),
            g.f(50.0, 3000.0)
        ));
    }
    for i in 1..=n {
        let pose = format!(
            "(pos: ({}, {}, {}), rpy: ({}, {}, {}))",
            g.f(-0.6, 0.6),
            g.f(-0.6, 0.6),
            g.f(0.05, 1.2),
            g.f(-3.1, 3.1),
            g.f(-3.1, 3.1),
            g.f(-3.1, 3.1)
        );
        // At most one FEM solid: two solids in contact can take seconds per step (docs/reliability.md).
        let kind = match g.below(3) {
            1 if solids > 0 => 2,
            k => k,
        };
        solids += usize::from(kind == 1);
        let (shape, body) = match kind {
            0 => {
                let body = match g.below(3) {
                    0 => "Static".to_string(),
                    1 => "Kinematic".to_string(),
                    _ => format!(
                        "Dynamic(linear_velocity: ({}, {}, {}))",
                        g.f(-2.0, 2.0),
                        g.f(-2.0, 2.0),
                        g.f(-2.0, 2.0)
                    ),
                };
                (g.rigid_shape(), body)
            }
            1 => (g.solid_shape(), g.fem_body()),
            _ => (g.cloth_shape(), g.cloth_body()),
        };
        objects.push(format!(
            "(name: \"o{i}\", shape: {shape}, pose: {pose}, body: {body}, material: Some(\"m{i}\"))"
        ));
    }
    format!(
        "Scene(\n    physics: (dt: {}, substeps: {substeps}),\n    materials: {{{}}},\n    objects: [\n        {},\n    ],\n    episode_steps: Some(400),\n)\n",
        [1.0 / 60.0, 1.0 / 120.0, 1.0 / 240.0][g.below(3)],
        materials.join(", "),
        objects.join(",\n        ")
    )
}

struct Gen(EnvRng);

impl Gen {
    fn below(&mut self, n: usize) -> usize {
        (self.0.next_u64() % n as u64) as usize
    }

    /// A uniform number in `[lo, hi]`, printed so RON reads it back exactly.
    fn f(&mut self, lo: f64, hi: f64) -> String {
        format!("{:?}", self.0.range(lo, hi))
    }

    /// A log-uniform number in `[lo, hi]`.
    fn log(&mut self, lo: f64, hi: f64) -> String {
        format!("{:?}", (self.0.range(lo.ln(), hi.ln())).exp())
    }

    fn rigid_shape(&mut self) -> String {
        match self.below(5) {
            4 => format!("Mesh(file: \"{SURFACE_MESH}\")"),
            0 => format!(
                "Box(size: ({}, {}, {}))",
                self.f(0.02, 0.5),
                self.f(0.02, 0.5),
                self.f(0.02, 0.5)
            ),
            1 => format!("Sphere(radius: {})", self.f(0.01, 0.3)),
            2 => format!(
                "Cylinder(radius: {}, height: {})",
                self.f(0.01, 0.3),
                self.f(0.02, 0.6)
            ),
            _ => format!(
                "Capsule(radius: {}, height: {})",
                self.f(0.01, 0.2),
                self.f(0.02, 0.6)
            ),
        }
    }

    fn solid_shape(&mut self) -> String {
        match self.below(9) {
            5 => format!(
                "Sweep(profile: Circle(radius: {}, segments: 6, rings: 1), path: Polyline(points: [(0.0, 0.0, 0.0), ({}, {}, 0.0), ({}, {}, {})]), segments: {})",
                self.f(0.005, 0.03),
                self.f(0.1, 0.3),
                self.f(-0.1, 0.1),
                self.f(0.35, 0.6),
                self.f(-0.2, 0.2),
                self.f(-0.1, 0.1),
                6 + self.below(20)
            ),
            6 => format!(
                "Sweep(profile: Polygon(points: [(0.0, 0.0), ({}, 0.0), (0.0, {})]), path: Arc(radius: {}, angle: {}), segments: {})",
                self.f(0.01, 0.04),
                self.f(0.01, 0.04),
                self.f(0.1, 0.4),
                self.f(0.5, 3.0),
                6 + self.below(18)
            ),
            7 => format!(
                "Sweep(profile: Circle(radius: {}, segments: 6, rings: 1), path: Helix(radius: {}, pitch: {}, turns: {}), segments: {})",
                self.f(0.005, 0.02),
                self.f(0.06, 0.2),
                self.f(0.05, 0.15),
                self.f(0.5, 2.5),
                8 + self.below(24)
            ),
            8 => match self.below(2) {
                0 => format!(
                    "Revolve(profile: Rect(width: {}, height: {}, divisions: Some((2, 1))), radius: {}, angle: {})",
                    self.f(0.01, 0.04),
                    self.f(0.005, 0.03),
                    self.f(0.08, 0.3),
                    self.f(1.0, 6.2)
                ),
                _ => format!("Mesh(file: \"{VOLUME_MESH}\")"),
            },
            0 => format!(
                "Box(size: ({}, {}, {}), divisions: ({}, {}, {}))",
                self.f(0.05, 0.8),
                self.f(0.02, 0.3),
                self.f(0.01, 0.2),
                1 + self.below(8),
                1 + self.below(3),
                1 + self.below(2)
            ),
            1 => format!(
                "Cylinder(radius: {}, height: {})",
                self.f(0.02, 0.15),
                self.f(0.05, 0.6)
            ),
            2 => format!(
                "Revolve(profile: Circle(radius: {}, segments: {}), radius: {}, segments: {})",
                self.f(0.01, 0.04),
                6 + self.below(6),
                self.f(0.08, 0.3),
                8 + self.below(16)
            ),
            3 => format!(
                "Sweep(profile: Rect(width: {}, height: {}, divisions: ({}, 1)), path: Line(length: {}), segments: {})",
                self.f(0.02, 0.1),
                self.f(0.003, 0.02),
                1 + self.below(3),
                self.f(0.2, 1.0),
                4 + self.below(20)
            ),
            _ => format!(
                "Extrude(polygon: [(0.0, 0.0), ({}, 0.0), ({}, {}), (0.0, {})], height: {}, layers: {})",
                self.f(0.05, 0.3),
                self.f(0.05, 0.3),
                self.f(0.05, 0.3),
                self.f(0.05, 0.3),
                self.f(0.02, 0.2),
                1 + self.below(3)
            ),
        }
    }

    fn fem_body(&mut self) -> String {
        format!(
            "Kind(kind: \"fem.solid\", params: (youngs_modulus: {}, poisson_ratio: {}, density: {}, rayleigh_mass: {}))",
            self.log(1e4, 1e8),
            self.f(0.0, 0.48),
            self.f(30.0, 3000.0),
            self.f(0.0, 2.0)
        )
    }

    fn cloth_shape(&mut self) -> String {
        format!(
            "Grid(size: ({}, {}), resolution: ({}, {}))",
            self.f(0.1, 1.2),
            self.f(0.1, 1.2),
            2 + self.below(16),
            2 + self.below(16)
        )
    }

    fn cloth_body(&mut self) -> String {
        format!(
            "Kind(kind: \"pbd.cloth\", params: (areal_density: {}, friction: {}))",
            self.f(0.02, 1.0),
            self.f(0.0, 1.2)
        )
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn same_seed_same_scene() {
        assert_eq!(super::random_scene(4), super::random_scene(4));
        assert_ne!(super::random_scene(4), super::random_scene(5));
    }
}
