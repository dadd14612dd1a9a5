//! Finite-element parent model: structured hex meshing ([`grid`]), the mesh data model
//! ([`mesh`]), element matrices ([`hex8`]), interface-layer springs and point masses,
//! sparse assembly into the free-DOF stiffness and mass matrices ([`assembly`], [`model`]),
//! the rig mesher that turns a rig description into a mesh ([`rig`]) and the CalculiX
//! exchange ([`calculix`]).

pub mod assembly;
pub mod calculix;
pub mod grid;
pub mod hex8;
pub mod mesh;
pub mod model;
pub mod rig;

pub use assembly::{assemble, FeError};
pub use mesh::{
    ContactPair, ElementBlock, ElementKind, HexElement, Material, Mesh, PointMass, SensorPoint,
    Spring,
};
pub use model::{DofGroup, DofInfo, FeModel, OutputDofs, PairDofs};
